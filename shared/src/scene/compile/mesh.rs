//! Triangles and meshes: faces into view-space triangles (winding, normals, uvs), then
//! written as leaves below their cluster in the hierarchy [`MeshHierarchy`] selects.

use super::*;

/// A triangle ready to write: view-space vertices and optional normals / uvs.
pub(super) struct TriData {
    pub(super) p: [[f32; 3]; 3],
    pub(super) n: Option<[[f32; 3]; 3]>,
    pub(super) uv: Option<[[f32; 2]; 3]>,
    pub(super) material: u32,
}

impl TriData {
    /// World -> view mirrors space (right-handed world, left-handed view), which would turn
    /// counter-clockwise (outward-facing) triangles clockwise: swap two vertices to undo it.
    pub(super) fn keep_winding(&mut self, full: &Affine) {
        if det(&full.a) < 0.0 {
            self.p.swap(1, 2);
            if let Some(n) = &mut self.n {
                n.swap(1, 2);
            }
            if let Some(uv) = &mut self.uv {
                uv.swap(1, 2);
            }
        }
    }
    /// Drop vertex normals that all equal the face normal: a flat face shades the same
    /// without them, and the image carries only what the scene needs.
    pub(super) fn drop_flat_normals(&mut self) {
        let Some(n) = self.n else { return };
        let v = self.p.map(|p| p.map(f64::from));
        let Some(face) = normalize(cross(sub(v[1], v[0]), sub(v[2], v[0]))) else {
            return;
        };
        let flat = n.iter().all(|vn| {
            let vn = vn.map(f64::from);
            // Same direction and orientation: without vertex normals the renderer takes the
            // outside from the winding, so only normals that agree with it may go.
            dot(vn, face) > 1.0 - 1e-6
        });
        if flat {
            self.n = None;
        }
    }

    pub(super) fn centroid(&self, axis: usize) -> f32 {
        (self.p[0][axis] + self.p[1][axis] + self.p[2][axis]) / 3.0
    }
    pub(super) fn bounds(&self) -> Bounds {
        // The stored vertices are f32 already, so their box is exact.
        let mut b = Bounds::empty();
        for v in &self.p {
            b = b.union(Bounds { min: *v, max: *v });
        }
        b
    }
}

impl Dm<'_> {
    pub(super) fn check_triangle(&self, t: &TriData, path: &str) -> Result<(), DmError> {
        let v = t.p.map(|p| p.map(f64::from));
        let area2 = cross(sub(v[1], v[0]), sub(v[2], v[0]));
        if dot(area2, area2) == 0.0 || !t.p.iter().flatten().all(|x| x.is_finite()) {
            return Err(DmError::DegenerateShape {
                cluster: path.to_string(),
                what: "a triangle".into(),
            });
        }
        Ok(())
    }

    pub(super) fn mesh_triangles(
        &self,
        mesh: &desc::Mesh,
        smooth: bool,
        material: u32,
        full: &Affine,
        normal_m: &M3,
        path: &str,
    ) -> Result<Vec<TriData>, DmError> {
        let bad = |what: String| DmError::BadIndex {
            what: format!("mesh '{}': {what}", mesh.source),
        };
        let pos = |i: u32| {
            mesh.positions
                .get(i as usize)
                .copied()
                .ok_or_else(|| bad(format!("position {i} missing")))
        };
        // Area-weighted vertex normals for smooth meshes without their own.
        let computed: Option<Vec<[f64; 3]>> = (smooth && mesh.normals.is_empty()).then(|| {
            let mut acc = vec![[0.0; 3]; mesh.positions.len()];
            for f in &mesh.faces {
                let p: Vec<[f64; 3]> = f
                    .iter()
                    .filter_map(|v| mesh.positions.get(v.position as usize).copied())
                    .collect();
                if p.len() == 3 {
                    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
                    for v in f {
                        if let Some(a) = acc.get_mut(v.position as usize) {
                            *a = add(*a, n);
                        }
                    }
                }
            }
            acc
        });
        let mut out = Vec::with_capacity(mesh.faces.len());
        for (fi, f) in mesh.faces.iter().enumerate() {
            let mut p = [[0.0f32; 3]; 3];
            let mut n = [[0.0f32; 3]; 3];
            let mut has_n = true;
            let mut uv = [[0.0f32; 2]; 3];
            let mut has_uv = true;
            for k in 0..3 {
                let v = f[k];
                p[k] = f32s(full.point(pos(v.position)?));
                let world_n = match (&computed, v.normal) {
                    (Some(c), _) => c.get(v.position as usize).copied(),
                    (None, Some(ni)) => Some(
                        mesh.normals
                            .get(ni as usize)
                            .copied()
                            .ok_or_else(|| bad(format!("normal {ni} missing")))?,
                    ),
                    (None, None) => None,
                };
                match world_n.and_then(|wn| normalize(mat_vec(normal_m, wn))) {
                    Some(vn) => n[k] = f32s(vn),
                    None => has_n = false,
                }
                match v.uv {
                    Some(ti) => {
                        let t = mesh
                            .uvs
                            .get(ti as usize)
                            .copied()
                            .ok_or_else(|| bad(format!("uv {ti} missing")))?;
                        uv[k] = [t[0] as f32, t[1] as f32];
                    }
                    None => has_uv = false,
                }
            }
            let mut tri = TriData {
                p,
                n: has_n.then_some(n),
                uv: has_uv.then_some(uv),
                material,
            };
            tri.keep_winding(full);
            tri.drop_flat_normals();
            self.check_triangle(
                &tri,
                &format!("{path} (mesh '{}', face {})", mesh.source, fi + 1),
            )?;
            out.push(tri);
        }
        Ok(out)
    }

    /// Write triangles as leaves of up to [`CompileOptions::leaf_size`] triangles (one
    /// material each), splitting into sub-clusters per [`MeshHierarchy`].
    pub(super) fn triangles(&mut self, mut tris: Vec<TriData>) -> Result<Bounds, DmError> {
        let leaf_size = self.leaf_size();
        let split = match self.opts.mesh_hierarchy {
            _ if tris.len() <= 1 => None,
            _ if tris.iter().any(|t| t.material != tris[0].material) => {
                Some(material_split(&mut tris))
            }
            MeshHierarchy::Flat => None,
            MeshHierarchy::Median if tris.len() <= leaf_size => None,
            MeshHierarchy::Median => Some(median_split(&mut tris)),
            MeshHierarchy::Sah => sah_split(&mut tris, leaf_size),
        };
        let Some(mid) = split else {
            // One leaf per run of at most `leaf_size` triangles (a flat hierarchy may give
            // more than one).
            let mut b = Bounds::empty();
            let mut rest = tris;
            while !rest.is_empty() {
                let tail = rest.split_off(rest.len().min(leaf_size));
                b = b.union(self.triangle_leaf(rest)?);
                rest = tail;
            }
            return Ok(b);
        };
        let right = tris.split_off(mid);
        let mut b = Bounds::empty();
        for half in [tris, right] {
            let node = self.open_node();
            let hb = self.triangles(half)?;
            self.close_node(node, hb);
            b = b.union(hb);
        }
        Ok(b)
    }

    /// Triangles per leaf: the option, within what a leaf can hold.
    pub(super) fn leaf_size(&self) -> usize {
        self.opts
            .leaf_size
            .unwrap_or(MESH_LEAF_SIZE)
            .clamp(1, node::MAX_LEAF as usize)
    }

    /// One leaf holding `tris` (1..=31 of one material), written consecutively.
    fn triangle_leaf(&mut self, tris: Vec<TriData>) -> Result<Bounds, DmError> {
        let mut b = Bounds::empty();
        let mut rect = Rect::EMPTY;
        let first = self.w.count(Section::Triangles);
        let (count, material) = (tris.len() as u32, tris[0].material);
        for t in tris {
            b = b.union(t.bounds());
            // Triangles are projected directly (LINKS-1 4.4): tighter than their box.
            rect = rect.union(self.proj.rect_of(&t.p.map(|p| p.map(f64::from))));
            self.write_triangle(t)?;
        }
        self.leaf_with_rect(
            Leaf {
                kind: ShapeKind::Triangle,
                first,
                count,
                material,
            },
            b,
            rect,
        );
        Ok(b)
    }

    /// The triangle's record, its vertices, normals and uvs shared with the triangles
    /// written before it.
    pub(super) fn write_triangle(&mut self, t: TriData) -> Result<u32, DmError> {
        let mut v = [0u16; 3];
        for (i, p) in v.iter_mut().zip(t.p) {
            *i = self.shared.vertex(&mut self.w, p)?;
        }
        let normals = match t.n {
            Some(n) => {
                let mut c = [0u16; 3];
                for (i, n) in c.iter_mut().zip(n) {
                    *i = self.shared.normal(&mut self.w, n)?;
                }
                let (i, r) = self.w.push(Section::TriNormals);
                r.hs(corners::I, &c);
                index16(i, "triangle normal triples")?
            }
            None => NONE16,
        };
        let uvs = match t.uv {
            Some(uv) => {
                let mut c = [0u16; 3];
                for (i, uv) in c.iter_mut().zip(uv) {
                    *i = self.shared.uv(&mut self.w, uv)?;
                }
                Some(c)
            }
            None => None,
        };
        self.tri_uvs.push(uvs);
        let (i, r) = self.w.push(Section::Triangles);
        r.hs(triangle::V, &v).h(triangle::NORMALS, normals);
        index16(i, "triangles")?;
        Ok(i)
    }
}

/// A record index as u16, or the error naming what overflowed.
pub(super) fn index16(i: u32, what: &str) -> Result<u16, DmError> {
    if i < NONE16 as u32 {
        Ok(i as u16)
    } else {
        Err(DmError::TooLarge {
            what: format!("more than {} {what} (indices are u16)", NONE16),
        })
    }
}

/// Vertex positions, normals and uvs written so far, by their bits: each is stored once.
#[derive(Default)]
pub(super) struct SharedVertices {
    positions: std::collections::HashMap<[u32; 3], u16>,
    normals: std::collections::HashMap<[i16; 3], u16>,
    uvs: std::collections::HashMap<[u32; 2], u16>,
}

impl SharedVertices {
    fn vertex(&mut self, w: &mut ImageWriter, p: [f32; 3]) -> Result<u16, DmError> {
        let key = p.map(f32::to_bits);
        record_once(
            &mut self.positions,
            key,
            w,
            Section::Vertices,
            "vertices",
            |r| {
                r.fs(vertex::P, &p);
            },
        )
    }
    /// A unit normal, compressed to i16 components (see [`normal`]).
    fn normal(&mut self, w: &mut ImageWriter, n: [f32; 3]) -> Result<u16, DmError> {
        let q = n.map(|c| (f64::from(c).clamp(-1.0, 1.0) * normal::SCALE).round() as i16);
        record_once(&mut self.normals, q, w, Section::Normals, "normals", |r| {
            r.hs(normal::N, &q.map(|c| c as u16));
        })
    }
    fn uv(&mut self, w: &mut ImageWriter, uv: [f32; 2]) -> Result<u16, DmError> {
        let key = uv.map(f32::to_bits);
        record_once(&mut self.uvs, key, w, Section::Uvs, "uvs", |r| {
            r.fs(uv::UV, &uv);
        })
    }
}

/// The index of the record `key` names: the one written before, or a new record of `section`
/// filled by `fill`.
fn record_once<K: core::hash::Hash + Eq>(
    seen: &mut std::collections::HashMap<K, u16>,
    key: K,
    w: &mut ImageWriter,
    section: Section,
    what: &str,
    fill: impl FnOnce(crate::image::writer::Rec<'_>),
) -> Result<u16, DmError> {
    if let Some(&i) = seen.get(&key) {
        return Ok(i);
    }
    let (i, r) = w.push(section);
    fill(r);
    let i = index16(i, what)?;
    seen.insert(key, i);
    Ok(i)
}

/// Put the triangles of the first triangle's material first (stable); returns how many.
fn material_split(tris: &mut [TriData]) -> usize {
    let m = tris[0].material;
    tris.sort_by_key(|t| t.material != m);
    tris.iter().take_while(|t| t.material == m).count()
}
