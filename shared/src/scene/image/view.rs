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
/// offset `off`: `None` for an empty texture or when any step of `off + w * h * 3` leaves
/// u32 (so a 32-bit usize holds every bound and `w`, `h` < 2^31).
pub(super) fn texel_range(w: u32, h: u32, off: u32) -> Option<(u32, u32)> {
    if w == 0 || h == 0 {
        return None;
    }
    let end = w.checked_mul(h)?.checked_mul(3)?.checked_add(off)?;
    Some((off, end))
}

/// Zeros standing in for a record outside its section (at least the largest record).
static ZERO_RECORD: [u8; 128] = [0; 128];

/// One fixed-size record, borrowed in place after a single bounds check so the field reads
/// below compile to plain loads (reading fields byte by byte with a check each cost ~240
/// instructions per node on a Cortex-M4F, measured under QEMU; a copy of the record ~40;
/// in place the loads alone).
pub(super) struct Record<'b, const N: usize>(pub(super) &'b [u8; N]);

impl<const N: usize> Record<'_, N> {
    #[inline(always)]
    pub(super) fn u(&self, o: usize) -> u32 {
        let r = &self.0;
        u32::from_le_bytes([r[o], r[o + 1], r[o + 2], r[o + 3]])
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
            texture: r.u(TEXTURE),
            target: match r.u(TARGET) {
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

    /// Texture `i`: its size and exactly its `width * height * 3` texel bytes. A texture
    /// a validated image does not hold (never the case for indices from its records) reads
    /// as one black texel.
    pub fn texture(&self, i: u32) -> TextureView<'a> {
        let r = self.record::<TEXTURE_SIZE>(Section::Textures, i);
        let (w, h) = (r.u(texture::WIDTH), r.u(texture::HEIGHT));
        let texels = self.sections.0[Section::Texels as usize];
        let rgb = texel_range(w, h, r.u(texture::TEXELS))
            .and_then(|(start, end)| texels.get(start as usize..end as usize));
        match rgb {
            Some(rgb) => TextureView {
                width: w,
                height: h,
                rgb,
            },
            None => TextureView {
                width: 1,
                height: 1,
                rgb: &ZERO_RECORD[..3],
            },
        }
    }

    pub fn node_count(&self) -> u32 {
        self.count(Section::Nodes)
    }

    #[inline]
    pub fn node<T: Real>(&self, i: u32) -> Node<T> {
        let r = self.record::<NODE_SIZE>(Section::Nodes, i);
        let shape = r.u(node::SHAPE);
        Node {
            bounds: Aabb {
                min: r.v3(node::MIN),
                max: r.v3(node::MAX),
            },
            skip: r.u(node::SKIP),
            shape: if shape == NONE {
                None
            } else {
                ShapeRef::decode(shape)
            },
        }
    }

    /// The skip index of node `i` (first node after its subtree), without decoding its box.
    #[inline]
    pub fn node_skip(&self, i: u32) -> u32 {
        self.record::<NODE_SIZE>(Section::Nodes, i).u(node::SKIP)
    }

    /// Whether node `i` is a leaf (holds a shape).
    #[inline]
    pub fn node_is_leaf(&self, i: u32) -> bool {
        self.record::<NODE_SIZE>(Section::Nodes, i).u(node::SHAPE) != NONE
    }

    /// Whether the DM wrote screen rectangles (needed for Y/X clipping).
    pub fn has_rects(&self) -> bool {
        self.count(Section::Rects) != 0
    }

    /// Screen rectangle of node `i` (requires [`Self::has_rects`]).
    #[inline]
    pub fn rect(&self, i: u32) -> Rect {
        let r = self.record::<RECT_SIZE>(Section::Rects, i).0;
        let h = |o: usize| u16::from_le_bytes([r[o], r[o + 1]]);
        Rect {
            x_lo: h(rect::X_LO),
            x_hi: h(rect::X_HI),
            y_lo: h(rect::Y_LO),
            y_hi: h(rect::Y_HI),
        }
    }

    #[inline]
    pub fn triangle<T: Real>(&self, i: u32) -> TriangleRec<T> {
        use triangle::*;
        let r = self.record::<SIZE>(Section::Triangles, i);
        TriangleRec {
            tri: Triangle {
                p: [
                    r.v3(P),
                    r.v3(P + VERTEX_STRIDE),
                    r.v3(P + 2 * VERTEX_STRIDE),
                ],
            },
            material: r.u(MATERIAL),
            normals: r.u(NORMALS),
            uvs: r.u(UVS),
        }
    }

    pub fn normals<T: Real>(&self, i: u32) -> [Vec3<T>; 3] {
        use normals::*;
        let r = self.record::<SIZE>(Section::Normals, i);
        [r.v3(N), r.v3(N + STRIDE), r.v3(N + 2 * STRIDE)]
    }

    pub fn uvs<T: Real>(&self, i: u32) -> [[T; 2]; 3] {
        use uvs::*;
        let at = self.rec(Section::Uvs, i) + UV;
        [
            [self.f(at), self.f(at + 4)],
            [self.f(at + STRIDE), self.f(at + STRIDE + 4)],
            [self.f(at + 2 * STRIDE), self.f(at + 2 * STRIDE + 4)],
        ]
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
