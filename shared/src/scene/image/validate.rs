//! Validation of a SceneImage: the header, every section's bounds and every cross-reference
//! are checked once in [`SceneView::new`], so that the view's accessors can never index out
//! of range and a walk of the node tree always ends.

use super::layout::*;
use super::view::{rd_u32, texel_range, Grid, Sections};
use super::{ImageError, SceneView};
use crate::num::Storage;

/// The section table: each section's (offset, count) and its record bytes.
type Table<'a> = ([(u32, u32); SECTION_COUNT], [&'a [u8]; SECTION_COUNT]);

impl<'a> SceneView<'a> {
    /// Check the header, every section's bounds and every cross-reference, so that the
    /// accessors can never index out of range.
    pub fn new(bytes: &'a [u8]) -> Result<Self, ImageError> {
        let storage = check_header(bytes)?;
        let (table, sections) = check_table(bytes)?;
        let view = Self {
            bytes,
            table,
            grid: read_grid(sections[Section::Camera as usize]),
            sections: Sections(sections),
            storage,
        };
        view.check_references()?;
        Ok(view)
    }

    /// Open bytes that already passed [`Self::new`] and have not changed since: the header
    /// and section table are checked again (O(sections), so every accessor stays inside
    /// `bytes` whatever they hold) but the O(records) walk of the cross-references is
    /// skipped. On bytes that never passed [`Self::new`] the accessors still cannot index
    /// out of range, but a walk of the node tree may read nonsense or not end.
    pub fn open_validated(bytes: &'a [u8]) -> Result<Self, ImageError> {
        let storage = check_header(bytes)?;
        let (table, sections) = check_table(bytes)?;
        Ok(Self {
            bytes,
            table,
            grid: read_grid(sections[Section::Camera as usize]),
            sections: Sections(sections),
            storage,
        })
    }
}

/// Magic, version, number format and total length; returns the number format.
fn check_header(bytes: &[u8]) -> Result<Storage, ImageError> {
    if bytes.len() < HEADER_SIZE {
        return Err(ImageError::TooShort {
            len: bytes.len() as u32,
        });
    }
    if bytes[0..MAGIC.len()] != MAGIC {
        return Err(ImageError::BadMagic);
    }
    let version = u16::from_le_bytes([bytes[VERSION_AT], bytes[VERSION_AT + 1]]);
    if version != VERSION {
        return Err(ImageError::UnsupportedVersion { found: version });
    }
    let Some(storage) = Storage::from_u8(bytes[STORAGE_AT]) else {
        return Err(ImageError::UnsupportedFormat {
            found: bytes[STORAGE_AT],
        });
    };
    if storage == Storage::F32 && bytes[SCALE_AT] != 0 {
        return Err(ImageError::UnsupportedFormat {
            found: bytes[STORAGE_AT],
        });
    }
    let total = rd_u32(bytes, LENGTH_AT);
    if usize::try_from(total).ok() != Some(bytes.len()) {
        return Err(ImageError::LengthMismatch {
            header: total,
            actual: u32::try_from(bytes.len()).unwrap_or(u32::MAX),
        });
    }
    Ok(storage)
}

/// Every section's offset is aligned and its records lie after the header, inside `bytes`.
fn check_table(bytes: &[u8]) -> Result<Table<'_>, ImageError> {
    let mut table = [(0u32, 0u32); SECTION_COUNT];
    let mut sections: [&[u8]; SECTION_COUNT] = [&[]; SECTION_COUNT];
    for (i, s) in Section::ALL.iter().enumerate() {
        let entry = TABLE_AT + TABLE_ENTRY_SIZE * i;
        let off = rd_u32(bytes, entry);
        let count = rd_u32(bytes, entry + 4);
        if !off.is_multiple_of(4) {
            return Err(ImageError::Misaligned { section: i as u8 });
        }
        if count > 0 {
            // Every size in u32 (the image is at most u32::MAX bytes long), checked: the
            // section's bytes, then a slice that exists (so a 32-bit usize holds it too).
            let out = ImageError::SectionOutOfBounds { section: i as u8 };
            let end = (s.record_size() as u32)
                .checked_mul(count)
                .and_then(|size| off.checked_add(size))
                .ok_or(out)?;
            if (off as usize) < HEADER_SIZE {
                return Err(out);
            }
            sections[i] = bytes.get(off as usize..end as usize).ok_or(out)?;
        }
        table[i] = (off, count);
    }
    Ok((table, sections))
}

/// The node grid and rectangle unit from the camera record (zeros without one; the camera
/// check then fails).
fn read_grid(camera_bytes: &[u8]) -> Grid {
    use camera::*;
    let w = |at: usize| rd_u32(camera_bytes, at);
    Grid {
        origin: [0, 4, 8].map(|k| w(GRID_ORIGIN + k)),
        step: [0, 4, 8].map(|k| w(GRID_STEP + k)),
        // Clamped so no shift of a rectangle can overflow, whatever the bytes hold (the
        // camera check rejects the raw value when it is out of range).
        rect_shift: w(RECT_SHIFT).min(MAX_RECT_SHIFT),
    }
}

/// A record that refers to something that is not there.
fn bad(s: Section, i: u32) -> ImageError {
    ImageError::BadReference {
        section: s as u8,
        record: i,
    }
}

/// A record holding a value outside its range.
fn bad_value(s: Section, i: u32) -> ImageError {
    ImageError::BadValue {
        section: s as u8,
        record: i,
    }
}

impl SceneView<'_> {
    // Not inlined into `new`: inlined, the view lives in `new`'s frame and the node loop
    // reloads the image's pointer and length from the stack on every record (3 loads per
    // node, +3.4% instructions per validation on the Cortex-M4F, measured by scripts/qemu-node).
    #[inline(never)]
    fn check_references(&self) -> Result<(), ImageError> {
        self.check_camera()?;
        self.check_materials_and_lights()?;
        self.check_textures()?;
        self.check_nodes()?;
        self.check_nesting()?;
        self.check_shapes()
    }

    /// Exactly one camera record, with a depth limit and u16 pixel sizes.
    fn check_camera(&self) -> Result<(), ImageError> {
        if self.count(Section::Camera) != 1 {
            return Err(ImageError::MissingCamera);
        }
        let camera = self.camera::<f32>();
        // Pixel coordinates are u16 in screen rectangles and clipping.
        let side = 1..=u16::MAX as u32;
        if camera.max_depth > MAX_DEPTH_LIMIT
            || !side.contains(&camera.width)
            || !side.contains(&camera.height)
            || self.u(self.rec(Section::Camera, 0) + camera::RECT_SHIFT) > camera::MAX_RECT_SHIFT
            || self.u(self.rec(Section::Camera, 0) + camera::FLAGS) & !camera::KNOWN_FLAGS != 0
            || !(1..=camera::MAX_AA).contains(&camera.aa)
        {
            return Err(bad_value(Section::Camera, 0));
        }
        Ok(())
    }

    fn check_materials_and_lights(&self) -> Result<(), ImageError> {
        let ntex = self.count(Section::Textures);
        let nmat = self.count(Section::Materials);
        for i in 0..nmat {
            use material::*;
            let r = self.record::<MATERIAL_SIZE>(Section::Materials, i);
            let tex = r.u(TEXTURE);
            let (target, flags, ambient) = (r.0[TARGET], r.0[FLAGS], r.h(AMBIENT));
            let ambient_ok = if flags & OWN_AMBIENT != 0 {
                (ambient as u32) < nmat
            } else {
                ambient == 0
            };
            if (tex != NONE && tex >= ntex)
                || target > MAX_TARGET
                || flags & !OWN_AMBIENT != 0
                || !ambient_ok
            {
                return Err(bad(Section::Materials, i));
            }
        }
        for i in 0..self.count(Section::Lights) {
            if self.u(self.rec(Section::Lights, i) + light::KIND) > 2 {
                return Err(bad_value(Section::Lights, i));
            }
        }
        Ok(())
    }

    /// Each texture's texels lie inside the texel section ([`texel_range`], the same
    /// checked arithmetic [`Self::texture`] uses), so sampling stays inside them.
    fn check_textures(&self) -> Result<(), ImageError> {
        let ntexels = self.count(Section::Texels);
        for i in 0..self.count(Section::Textures) {
            let r = self.record::<TEXTURE_SIZE>(Section::Textures, i);
            match texel_range(
                r.u(texture::WIDTH),
                r.u(texture::HEIGHT),
                r.u(texture::TEXELS),
                r.u(texture::PALETTE),
            ) {
                Some((_, end)) if end <= ntexels => {}
                _ => return Err(bad(Section::Textures, i)),
            }
        }
        Ok(())
    }

    /// One tree whose skips move forward and whose leaves name existing shapes.
    fn check_nodes(&self) -> Result<(), ImageError> {
        let nnodes = self.count(Section::Nodes);
        // One tree: node 0 is the root and its subtree is the whole list.
        if nnodes == 0 || self.node_skip(0) != nnodes {
            return Err(bad(Section::Nodes, 0));
        }
        let nmat = self.count(Section::Materials);
        for i in 0..nnodes {
            let r = self.record::<NODE_SIZE>(Section::Nodes, i);
            let info = r.0[node::INFO];
            if info == 0 {
                let skip = r.h(node::INDEX) as u32;
                if skip <= i || skip > nnodes {
                    return Err(bad(Section::Nodes, i));
                }
                continue;
            }
            let leaf = Leaf::decode(info, r.h(node::INDEX), r.0[node::MATERIAL])
                .ok_or(bad(Section::Nodes, i))?;
            let triangle_material_ok = leaf.kind != ShapeKind::Triangle || leaf.material < nmat;
            if leaf.count == 0
                || leaf.first + leaf.count > self.count(leaf.kind.section())
                || !triangle_material_ok
            {
                return Err(bad(Section::Nodes, i));
            }
        }
        Ok(())
    }

    /// Subtrees nest: every child's subtree ends within its parent's (else a walk could
    /// visit nodes along exponentially many paths). O(n): each node is one child.
    fn check_nesting(&self) -> Result<(), ImageError> {
        for i in 0..self.count(Section::Nodes) {
            if self.node_is_leaf(i) {
                continue;
            }
            let end = self.node_skip(i);
            let mut c = i + 1;
            while c < end {
                let next = self.node_skip(c);
                if next > end {
                    return Err(bad(Section::Nodes, c));
                }
                c = next;
            }
        }
        Ok(())
    }

    /// Screen rectangles (if any) for every node; every shape's material, normals, uvs and
    /// balls exist.
    fn check_shapes(&self) -> Result<(), ImageError> {
        let (nnodes, nrects) = (self.count(Section::Nodes), self.count(Section::Rects));
        if nrects != 0 && nrects != nnodes {
            return Err(bad(Section::Rects, nrects));
        }
        let nmat = self.count(Section::Materials);
        let (ntri, nverts) = (
            self.count(Section::Triangles),
            self.count(Section::Vertices),
        );
        let ntn = self.count(Section::TriNormals);
        for i in 0..ntri {
            let r = self.record::<TRIANGLE_SIZE>(Section::Triangles, i);
            let v = [0, 2, 4].map(|k| r.h(triangle::V + k) as u32);
            let n = r.h(triangle::NORMALS);
            if v.iter().any(|&v| v >= nverts) || (n != NONE16 && n as u32 >= ntn) {
                return Err(bad(Section::Triangles, i));
            }
        }
        self.check_corners(Section::TriNormals, Section::Normals, false)?;
        let ntu = self.count(Section::TriUvs);
        if ntu != 0 && ntu != ntri {
            return Err(bad(Section::TriUvs, ntu));
        }
        self.check_corners(Section::TriUvs, Section::Uvs, true)?;
        for i in 0..self.count(Section::Ellipsoids) {
            if self.u(self.rec(Section::Ellipsoids, i) + ellipsoid::MATERIAL) >= nmat {
                return Err(bad(Section::Ellipsoids, i));
            }
        }
        for i in 0..self.count(Section::Boxes) {
            if self.u(self.rec(Section::Boxes, i) + boxshape::MATERIAL) >= nmat {
                return Err(bad(Section::Boxes, i));
            }
        }
        // A group's balls are records first..first + count, so `first + k` never wraps.
        let nballs = self.count(Section::Balls);
        for i in 0..self.count(Section::BlobGroups) {
            use blob_group::*;
            let at = self.rec(Section::BlobGroups, i);
            let (m, k) = (self.u(at + MATERIAL), self.u(at + KERNEL));
            let (first, count) = (self.u(at + FIRST), self.u(at + COUNT));
            let end = first.checked_add(count);
            if m >= nmat || k > 1 || count == 0 || end.is_none_or(|e| e > nballs) {
                return Err(bad(Section::BlobGroups, i));
            }
        }
        Ok(())
    }

    /// Every index of a corners section names a record of `target` (or is [`NONE16`] on
    /// all three corners, where `absent_ok`).
    fn check_corners(
        &self,
        s: Section,
        target: Section,
        absent_ok: bool,
    ) -> Result<(), ImageError> {
        let n = self.count(target);
        for i in 0..self.count(s) {
            let r = self.record::<CORNERS_SIZE>(s, i);
            let c = [0, 2, 4].map(|k| r.h(corners::I + k));
            let absent = absent_ok && c == [NONE16; 3];
            if !absent && c.iter().any(|&k| k as u32 >= n) {
                return Err(bad(s, i));
            }
        }
        Ok(())
    }
}
