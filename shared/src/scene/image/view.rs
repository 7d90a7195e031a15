//! [`SceneView`]: the zero-copy view of a validated SceneImage that a node renders from.
//!
//! Every accessor reads its record in place through the offsets of [`super::layout`]; the
//! checks that make those reads safe are in [`super::validate`].

use super::layout::*;
use super::{
    BlobGroupRec, BoxRec, Camera, EllipsoidRec, ImageError, Light, LightKind, MapTarget, Material,
    Node, TextureView, TriangleRec,
};
use crate::geom::{Aabb, Mat3, Vec3};
use crate::math::solid::{Ball, BoxShape, CutPlane, Ellipsoid, Kernel, Triangle};
use crate::num::{Real, Storage};

/// A validated, zero-copy view of a SceneImage.
#[derive(Clone, Copy, Debug)]
pub struct SceneView<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) table: [(u32, u32); SECTION_COUNT],
    /// Each section's records (exactly count x record size bytes), so that fetching record
    /// `i` is one compare of `i` against the count.
    pub(super) sections: Sections<'a>,
    pub(super) storage: Storage,
    /// The node grid's origin and step per axis, as stored (read once from the camera).
    pub(super) grid: Grid,
}

/// The node grid (see [`camera::GRID_ORIGIN`]) and the rectangles' unit, as stored.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Grid {
    pub(super) origin: [u32; 3],
    pub(super) step: [u32; 3],
    pub(super) rect_shift: u32,
}

#[derive(Clone, Copy)]
pub(super) struct Sections<'a>(pub(super) [&'a [u8]; SECTION_COUNT]);

impl core::fmt::Debug for Sections<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_list()
            .entries(self.0.iter().map(|s| s.len()))
            .finish()
    }
}

/// A little-endian u32 at `at`, or 0 outside `b` (never the case in a validated image).
#[inline(always)]
pub(super) fn rd_u32(b: &[u8], at: usize) -> u32 {
    // `get(at..)` then the first 4 bytes: one compare each, no overflow check of `at + 4`.
    match b.get(at..).and_then(|r| r.first_chunk::<4>()) {
        Some(&w) => u32::from_le_bytes(w),
        None => 0,
    }
}

/// The texel bytes `start..end` (within the texel section) of a `w` x `h` texture at
/// offset `off` with `palette` colours (0: RGB8 texels): `None` for an empty texture, a
/// palette over [`texture::MAX_PALETTE`] colours, or when any step of the size leaves u32
/// (so a 32-bit usize holds every bound and `w`, `h` < 2^31).
pub(super) fn texel_range(w: u32, h: u32, off: u32, palette: u32) -> Option<(u32, u32)> {
    if w == 0 || h == 0 || palette > texture::MAX_PALETTE {
        return None;
    }
    let per_texel = if palette == 0 { 3 } else { 1 };
    let end = w
        .checked_mul(h)?
        .checked_mul(per_texel)?
        .checked_add(palette * 3)?
        .checked_add(off)?;
    Some((off, end))
}

/// Zeros standing in for a record outside its section (at least the largest record).
static ZERO_RECORD: [u8; 128] = [0; 128];

/// One fixed-size record, borrowed in place after a single bounds check so the field reads
/// below compile to plain loads (reading fields byte by byte with a check each cost ~240
/// instructions per node on a Cortex-M4F, measured under QEMU; a copy of the record ~40;
/// in place the loads alone).
pub(super) struct Record<'b, const N: usize>(pub(super) &'b [u8; N]);

/// The node section as a walk reads it, kept in a local by the walk (so the section is not
/// re-read from the view at every node).
#[derive(Clone, Copy)]
pub struct NodeTable<'a> {
    records: &'a [[u8; NODE_SIZE]],
    grid: Grid,
}

impl<'a> NodeTable<'a> {
    /// How many nodes the tree has.
    #[inline(always)]
    pub fn len(&self) -> u32 {
        self.records.len() as u32
    }

    /// Whether the tree is empty.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Node `i` (all zeros, a childless cluster with an empty box, when `i` is not a node,
    /// which indices from a validated image never are).
    #[inline(always)]
    pub fn get(&self, i: u32) -> NodeRef<'a> {
        let r = self.records.get(i as usize).unwrap_or(&[0; NODE_SIZE]);
        NodeRef { r, grid: self.grid }
    }
}

/// One node record, decoded a part at a time: a traversal that rejects a node on one axis of
/// its box decodes neither the other axes nor its leaf. Every part is decoded exactly as
/// [`SceneView::node`] decodes it. (The grid is carried by value: behind a reference the
/// clipped primary-ray loop spilled it, +40 instructions per pixel on the M4F.)
#[derive(Clone, Copy)]
pub struct NodeRef<'a> {
    r: &'a [u8; NODE_SIZE],
    grid: Grid,
}

impl NodeRef<'_> {
    /// The box along `axis` (0..=2; larger reads as 2): (`min`, `max`).
    #[inline(always)]
    pub fn span<T: Real>(&self, axis: usize) -> (T, T) {
        let k = axis.min(2);
        let r = Record(self.r);
        let g = &self.grid;
        let c = |q: u16| {
            T::from_stored(g.origin[k]) + T::from_i32(q as i16 as i32) * T::from_stored(g.step[k])
        };
        (c(r.h(node::LO + 2 * k)), c(r.h(node::HI + 2 * k)))
    }

    /// The box along `axis` as a ray crosses it: (entry bound, exit bound), the upper bound
    /// first when the ray runs towards negative coordinates (`negative`). Decoded as
    /// [`Self::span`] decodes it.
    #[inline(always)]
    pub fn slab<T: Real>(&self, axis: usize, negative: bool) -> (T, T) {
        let k = axis.min(2);
        let r = Record(self.r);
        let g = &self.grid;
        let c = |q: u16| {
            T::from_stored(g.origin[k]) + T::from_i32(q as i16 as i32) * T::from_stored(g.step[k])
        };
        let (near, far) = if negative {
            (node::HI, node::LO)
        } else {
            (node::LO, node::HI)
        };
        (c(r.h(near + 2 * k)), c(r.h(far + 2 * k)))
    }

    /// The leaf's primitives (`None` for a cluster).
    #[inline(always)]
    pub fn leaf(&self) -> Option<Leaf> {
        Leaf::decode(
            self.r[node::INFO],
            Record(self.r).h(node::INDEX),
            self.r[node::MATERIAL],
        )
    }

    /// The first node after this one's subtree, this node being node `i`.
    #[inline(always)]
    pub fn skip(&self, i: u32) -> u32 {
        if self.r[node::INFO] != 0 {
            i + 1
        } else {
            Record(self.r).h(node::INDEX) as u32
        }
    }
}

impl<const N: usize> Record<'_, N> {
    #[inline(always)]
    pub(super) fn u(&self, o: usize) -> u32 {
        let r = &self.0;
        u32::from_le_bytes([r[o], r[o + 1], r[o + 2], r[o + 3]])
    }
    #[inline(always)]
    pub(super) fn h(&self, o: usize) -> u16 {
        let r = &self.0;
        u16::from_le_bytes([r[o], r[o + 1]])
    }
    #[inline(always)]
    fn f<T: Real>(&self, o: usize) -> T {
        T::from_stored(self.u(o))
    }
    #[inline(always)]
    fn v3<T: Real>(&self, o: usize) -> Vec3<T> {
        Vec3::new(self.f(o), self.f(o + 4), self.f(o + 8))
    }
    #[inline(always)]
    fn m3<T: Real>(&self, o: usize) -> Mat3<T> {
        Mat3 {
            r: [self.v3(o), self.v3(o + 12), self.v3(o + 24)],
        }
    }
}

impl<'a> SceneView<'a> {
    /// Unit round-off of the stored scalars: error bounds of quantities the DM rounded
    /// separately (a matrix and its inverse) are multiples of it. For Q16.16 it is one step
    /// relative to 1 (the DM scales a scene so its coordinates are well above 1).
    pub fn storage_epsilon<T: Real>(&self) -> T {
        match self.storage {
            Storage::F32 => T::from_f32(f32::EPSILON * 0.5),
            Storage::Q16_16 => T::from_f32(1.0 / 65536.0),
        }
    }

    /// How this image stores its scalars.
    pub fn storage(&self) -> Storage {
        self.storage
    }

    /// The power of two the DM scaled the scene's lengths by (0 for f32 images): a length
    /// in the image is the view-space length times 2^scale_exponent.
    pub fn scale_exponent(&self) -> i8 {
        self.bytes[SCALE_AT] as i8
    }

    /// Whether number type `T` reads this image's scalars: an image is rendered by the
    /// backends of its own storage format only.
    pub fn check_storage<T: Real>(&self) -> Result<(), ImageError> {
        if T::STORAGE == self.storage {
            Ok(())
        } else {
            Err(ImageError::WrongNumberType {
                image: self.storage,
                wanted: T::STORAGE,
            })
        }
    }

    /// The raw bytes (for sending over the link).
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Number of records in a section.
    pub fn count(&self, s: Section) -> u32 {
        self.table[s as usize].1
    }

    /// Bytes a section occupies.
    pub fn section_bytes(&self, s: Section) -> usize {
        self.sections.0[s as usize].len()
    }

    /// The bytes of record `i` of section `s` within [`Self::bytes`] (`None` unless `i` is
    /// one of the section's records), for tools that rewrite records in place.
    pub fn record_range(&self, s: Section, i: u32) -> Option<core::ops::Range<usize>> {
        if i >= self.count(s) {
            return None;
        }
        let size = s.record_size();
        let start =
            (self.table[s as usize].0 as usize).checked_add((i as usize).checked_mul(size)?)?;
        Some(start..start.checked_add(size)?)
    }

    /// Byte offset of record `i` of section `s` (saturating: an impossible index reads
    /// nothing rather than wrapping onto other bytes).
    #[inline(always)]
    pub(super) fn rec(&self, s: Section, i: u32) -> usize {
        (self.table[s as usize].0 as usize)
            .saturating_add((i as usize).saturating_mul(s.record_size()))
    }

    /// Record `i` of section `s` (N = its record size); all zeros when `i` is not a record
    /// of the section, which indices taken from a validated image never are.
    #[inline(always)]
    pub(super) fn record<const N: usize>(&self, s: Section, i: u32) -> Record<'a, N> {
        debug_assert_eq!(N, s.record_size());
        let (records, _) = self.sections.0[s as usize].as_chunks::<N>();
        if let Some(r) = records.get(i as usize) {
            return Record(r);
        }
        match ZERO_RECORD.first_chunk::<N>() {
            Some(z) => Record(z),
            None => panic!("record larger than ZERO_RECORD"),
        }
    }
    #[inline(always)]
    pub(super) fn u(&self, at: usize) -> u32 {
        rd_u32(self.bytes, at)
    }
    #[inline(always)]
    fn f<T: Real>(&self, at: usize) -> T {
        T::from_stored(rd_u32(self.bytes, at))
    }
    #[inline]
    fn v3<T: Real>(&self, at: usize) -> Vec3<T> {
        Vec3::new(self.f(at), self.f(at + 4), self.f(at + 8))
    }

    pub fn camera<T: Real>(&self) -> Camera<T> {
        use camera::*;
        let at = self.rec(Section::Camera, 0);
        Camera {
            width: self.u(at + WIDTH),
            height: self.u(at + HEIGHT),
            x0: self.f(at + X0),
            y0: self.f(at + Y0),
            dx: self.f(at + DX),
            dy: self.f(at + DY),
            dz: self.f(at + DZ),
            background: self.v3(at + BACKGROUND),
            ambient: self.v3(at + AMBIENT),
            max_depth: self.u(at + MAX_DEPTH),
            non_refractive: self.u(at + FLAGS) & NON_REFRACTIVE != 0,
            no_shadows: self.u(at + FLAGS) & NO_SHADOWS != 0,
            aa: ((self.u(at + FLAGS) & AA_MASK) >> AA_SHIFT) + 1,
        }
    }

    /// Material `i` (`i` comes from a validated record).
    pub fn material<T: Real>(&self, i: u32) -> Material<T> {
        use material::*;
        let r = self.record::<SIZE>(Section::Materials, i);
        Material {
            diffuse: r.v3(DIFFUSE),
            specular: r.f(SPECULAR),
            specular_edge: r.f(SPECULAR_EDGE),
            shininess: r.f(SHININESS),
            reflect: r.f(REFLECT),
            reflect_edge: r.f(REFLECT_EDGE),
            transmit: r.v3(TRANSMIT),
            ior: r.f(IOR),
            ambient: if r.0[FLAGS] & OWN_AMBIENT != 0 {
                let a = self.record::<SIZE>(Section::Materials, r.h(AMBIENT) as u32);
                Some(a.v3(DIFFUSE))
            } else {
                None
            },
            texture: r.u(TEXTURE),
            target: match r.0[TARGET] {
                1 => MapTarget::Specular,
                2 => MapTarget::Reflect,
                3 => MapTarget::Transmit,
                _ => MapTarget::Diffuse,
            },
            scale: [r.f(SCALE), r.f(SCALE + 4)],
        }
    }

    pub fn light_count(&self) -> u32 {
        self.count(Section::Lights)
    }

    pub fn light<T: Real>(&self, i: u32) -> Light<T> {
        use light::*;
        let r = self.record::<SIZE>(Section::Lights, i);
        Light {
            kind: match r.u(KIND) {
                1 => LightKind::Point,
                2 => LightKind::Spot,
                _ => LightKind::Directional,
            },
            color: r.v3(COLOR),
            pos: r.v3(POS),
            dir: r.v3(DIR),
            cos_inner: r.f(COS_INNER),
            cos_outer: r.f(COS_OUTER),
            exponent: r.f(EXPONENT),
            falloff: r.u(FALLOFF) != 0,
        }
    }

    /// Texture `i`: its size, exactly its texel bytes and its palette. A texture a
    /// validated image does not hold (never the case for indices from its records) reads as
    /// one black texel.
    pub fn texture(&self, i: u32) -> TextureView<'a> {
        let r = self.record::<TEXTURE_SIZE>(Section::Textures, i);
        let (w, h, p) = (
            r.u(texture::WIDTH),
            r.u(texture::HEIGHT),
            r.u(texture::PALETTE),
        );
        let texels = self.sections.0[Section::Texels as usize];
        let bytes = texel_range(w, h, r.u(texture::TEXELS), p)
            .and_then(|(start, end)| texels.get(start as usize..end as usize));
        match bytes {
            Some(b) => {
                let (palette, texels) = b.split_at((p * 3) as usize);
                TextureView {
                    width: w,
                    height: h,
                    texels,
                    palette,
                }
            }
            None => TextureView {
                width: 1,
                height: 1,
                texels: &ZERO_RECORD[..3],
                palette: &[],
            },
        }
    }

    pub fn node_count(&self) -> u32 {
        self.count(Section::Nodes)
    }

    /// The box of grid corners `q` (exact in every number type: see
    /// [`camera::GRID_ORIGIN`]).
    #[inline(always)]
    fn grid_point<T: Real>(&self, q: [u16; 3]) -> Vec3<T> {
        // Grid coordinates are i16 (so Q16.16 holds them as integers).
        let g = &self.grid;
        let c = |k: usize| {
            T::from_stored(g.origin[k])
                + T::from_i32(q[k] as i16 as i32) * T::from_stored(g.step[k])
        };
        Vec3::new(c(0), c(1), c(2))
    }

    #[inline]
    pub fn node<T: Real>(&self, i: u32) -> Node<T> {
        use node::*;
        let r = self.record::<NODE_SIZE>(Section::Nodes, i);
        let index = r.h(INDEX);
        let leaf = Leaf::decode(r.0[INFO], index, r.0[MATERIAL]);
        Node {
            bounds: Aabb {
                min: self.grid_point([r.h(LO), r.h(LO + 2), r.h(LO + 4)]),
                max: self.grid_point([r.h(HI), r.h(HI + 2), r.h(HI + 4)]),
            },
            skip: if leaf.is_some() { i + 1 } else { index as u32 },
            leaf,
        }
    }

    /// Node `i` alone, to decode a part at a time ([`NodeRef`]); walks over many nodes take
    /// the [`NodeTable`] once instead.
    #[inline(always)]
    pub fn node_ref(&self, i: u32) -> NodeRef<'a> {
        NodeRef {
            r: self.record::<NODE_SIZE>(Section::Nodes, i).0,
            grid: self.grid,
        }
    }

    /// The node section for a walk ([`NodeTable`]).
    #[inline(always)]
    pub fn node_table(&self) -> NodeTable<'a> {
        NodeTable {
            records: self.sections.0[Section::Nodes as usize]
                .as_chunks::<NODE_SIZE>()
                .0,
            grid: self.grid,
        }
    }

    /// The skip index of node `i` (first node after its subtree), without decoding its box.
    #[inline]
    pub fn node_skip(&self, i: u32) -> u32 {
        let r = self.record::<NODE_SIZE>(Section::Nodes, i);
        if r.0[node::INFO] != 0 {
            i + 1
        } else {
            r.h(node::INDEX) as u32
        }
    }

    /// Whether node `i` is a leaf (holds primitives).
    #[inline]
    pub fn node_is_leaf(&self, i: u32) -> bool {
        self.record::<NODE_SIZE>(Section::Nodes, i).0[node::INFO] != 0
    }

    /// The primitives of leaf `i` (`None` for a cluster), without decoding its box.
    #[inline]
    pub fn node_leaf(&self, i: u32) -> Option<Leaf> {
        let r = self.record::<NODE_SIZE>(Section::Nodes, i);
        Leaf::decode(r.0[node::INFO], r.h(node::INDEX), r.0[node::MATERIAL])
    }

    /// Whether the DM wrote screen rectangles (needed for Y/X clipping).
    pub fn has_rects(&self) -> bool {
        self.count(Section::Rects) != 0
    }

    /// Screen rectangle of node `i` in pixels (requires [`Self::has_rects`]).
    #[inline]
    pub fn rect(&self, i: u32) -> Rect {
        let r = self.record::<RECT_SIZE>(Section::Rects, i).0;
        let s = self.grid.rect_shift;
        let lo = |o: usize| (r[o] as u16) << s;
        let hi = |o: usize| ((r[o] as u16) << s) | ((1u16 << s) - 1);
        Rect {
            x_lo: lo(rect::X_LO),
            x_hi: hi(rect::X_HI),
            y_lo: lo(rect::Y_LO),
            y_hi: hi(rect::Y_HI),
        }
    }

    /// Triangle `i`: its vertices read through their indices.
    #[inline]
    pub fn triangle<T: Real>(&self, i: u32) -> TriangleRec<T> {
        use triangle::*;
        let r = self.record::<TRIANGLE_SIZE>(Section::Triangles, i);
        let v = |k: usize| {
            let p = self.record::<VERTEX_SIZE>(Section::Vertices, r.h(V + 2 * k) as u32);
            p.v3(vertex::P)
        };
        let n = r.h(NORMALS);
        TriangleRec {
            tri: Triangle {
                p: [v(0), v(1), v(2)],
            },
            normals: if n == NONE16 { NONE } else { n as u32 },
            uvs: if self.count(Section::TriUvs) != 0 {
                i
            } else {
                NONE
            },
        }
    }

    /// Triangle `i`'s vertex indices and vertices (shared vertices share an index).
    #[inline]
    pub fn triangle_corners<T: Real>(&self, i: u32) -> ([u32; 3], Triangle<T>) {
        use triangle::*;
        let r = self.record::<TRIANGLE_SIZE>(Section::Triangles, i);
        let index = [r.h(V) as u32, r.h(V + 2) as u32, r.h(V + 4) as u32];
        let v = |k: usize| {
            self.record::<VERTEX_SIZE>(Section::Vertices, index[k])
                .v3(vertex::P)
        };
        (
            index,
            Triangle {
                p: [v(0), v(1), v(2)],
            },
        )
    }

    /// The three indices of record `i` of a corners section ([`NONE16`] when absent).
    #[inline]
    fn corners(&self, s: Section, i: u32) -> [u16; 3] {
        let r = self.record::<CORNERS_SIZE>(s, i);
        [r.h(corners::I), r.h(corners::I + 2), r.h(corners::I + 4)]
    }

    /// The vertex normals of TriNormals record `i`.
    pub fn normals<T: Real>(&self, i: u32) -> [Vec3<T>; 3] {
        // 2^-15 is exact in every number type; the interpolated normal is normalised.
        let scale = T::from_f32(1.0 / 32768.0);
        self.corners(Section::TriNormals, i).map(|n| {
            let r = self.record::<NORMAL_SIZE>(Section::Normals, n as u32);
            let c = |k: usize| T::from_i32(r.h(normal::N + 2 * k) as i16 as i32) * scale;
            Vec3::new(c(0), c(1), c(2))
        })
    }

    /// The vertex texture coordinates of TriUvs record `i` (`None` for a triangle without).
    pub fn uvs<T: Real>(&self, i: u32) -> Option<[[T; 2]; 3]> {
        let c = self.corners(Section::TriUvs, i);
        if c.contains(&NONE16) {
            return None;
        }
        Some(c.map(|k| {
            let r = self.record::<UV_SIZE>(Section::Uvs, k as u32);
            [r.f(uv::UV), r.f(uv::UV + 4)]
        }))
    }

    #[inline]
    pub fn ellipsoid<T: Real>(&self, i: u32) -> EllipsoidRec<T> {
        use ellipsoid::*;
        let r = self.record::<SIZE>(Section::Ellipsoids, i);
        let flags = r.u(FLAGS);
        let cut = if flags & CUT != 0 {
            Some(CutPlane {
                n: r.v3(CUT_N),
                d: r.f(CUT_D),
                capped: flags & CAPPED != 0,
            })
        } else {
            None
        };
        EllipsoidRec {
            shape: Ellipsoid {
                center: r.v3(CENTER),
                m: r.m3(TO_UNIT),
                l: r.m3(TO_VIEW),
                cut,
            },
            material: r.u(MATERIAL),
        }
    }

    #[inline]
    pub fn boxshape<T: Real>(&self, i: u32) -> BoxRec<T> {
        use boxshape::*;
        let r = self.record::<SIZE>(Section::Boxes, i);
        BoxRec {
            shape: BoxShape {
                center: r.v3(CENTER),
                m: r.m3(TO_UNIT),
                l: r.m3(TO_VIEW),
            },
            material: r.u(MATERIAL),
        }
    }

    pub fn blob_group<T: Real>(&self, i: u32) -> BlobGroupRec<T> {
        use blob_group::*;
        let at = self.rec(Section::BlobGroups, i);
        BlobGroupRec {
            material: self.u(at + MATERIAL),
            kernel: if self.u(at + KERNEL) == 1 {
                Kernel::Wyvill
            } else {
                Kernel::Links
            },
            threshold: self.f(at + THRESHOLD),
            first: self.u(at + FIRST),
            count: self.u(at + COUNT),
        }
    }

    #[inline]
    pub fn ball<T: Real>(&self, i: u32) -> Ball<T> {
        use ball::*;
        let r = self.record::<SIZE>(Section::Balls, i);
        Ball {
            center: r.v3(CENTER),
            radius: r.f(RADIUS),
            strength: r.f(STRENGTH),
        }
    }
}
