//! One TRIANGLES primitive -> [`Shape::Mesh`]: positions, normals, TEXCOORD_0 (v flipped:
//! glTF's v runs down the image, ours up), indices checked against the vertex count.

use links_core::desc::{FaceVertex, Mesh, Shape};

use super::buffers::check_accessor;
use super::error::GltfError;
use super::warning::Warning;
use super::Importer;

impl Importer<'_> {
    /// The shapes of `mesh`'s primitives (non-triangle ones skipped with a warning).
    pub(super) fn mesh_shapes(&mut self, mesh: &gltf::Mesh<'_>) -> Result<Vec<Shape>, GltfError> {
        let name = mesh
            .name()
            .map_or_else(|| format!("mesh {}", mesh.index()), str::to_string);
        let mut shapes = Vec::new();
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                self.warnings.push(Warning::PrimitiveMode {
                    mesh: name.clone(),
                    mode: format!("{:?}", prim.mode()),
                });
                continue;
            }
            let targets = prim.morph_targets().count();
            if targets > 0 {
                self.warnings.push(Warning::MorphTargets {
                    mesh: name.clone(),
                    targets,
                });
            }
            let material = self.material_index(&prim.material())?;
            let mesh_desc = self.primitive_mesh(mesh.index(), &prim, &name)?;
            let smooth = false;
            shapes.push(Shape::Mesh {
                mesh: mesh_desc,
                material,
                smooth,
            });
        }
        Ok(shapes)
    }

    fn primitive_mesh(
        &self,
        mesh: usize,
        prim: &gltf::Primitive<'_>,
        name: &str,
    ) -> Result<Mesh, GltfError> {
        for (_, accessor) in prim.attributes() {
            check_accessor(&accessor, &self.buffers, &self.file)?;
        }
        if let Some(a) = prim.indices() {
            check_accessor(&a, &self.buffers, &self.file)?;
        }
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let positions: Vec<[f64; 3]> = reader
            .read_positions()
            .ok_or_else(|| GltfError::Invalid {
                file: self.file.clone(),
                path: format!("meshes[{mesh}].primitives[{}].attributes", prim.index()),
                message: "no POSITION attribute".into(),
            })?
            .map(|p| p.map(f64::from))
            .collect();
        let n = positions.len();
        let normals: Vec<[f64; 3]> = reader
            .read_normals()
            .map(|it| it.map(|v| v.map(f64::from)).collect())
            .unwrap_or_default();
        let uvs: Vec<[f64; 2]> = reader
            .read_tex_coords(0)
            .map(|it| {
                it.into_f32()
                    .map(|[u, v]| [f64::from(u), 1.0 - f64::from(v)])
                    .collect()
            })
            .unwrap_or_default();
        let indices: Vec<u32> = match reader.read_indices() {
            Some(it) => it.into_u32().collect(),
            None => (0..u32::try_from(n).unwrap_or(u32::MAX)).collect(),
        };
        let has_n = normals.len() == n;
        let has_uv = uvs.len() == n;
        let mut faces = Vec::with_capacity(indices.len() / 3);
        for tri in indices.chunks_exact(3) {
            let mut fv = [FaceVertex {
                position: 0,
                normal: None,
                uv: None,
            }; 3];
            for (k, &i) in tri.iter().enumerate() {
                if i as usize >= n {
                    return Err(GltfError::VertexIndex {
                        file: self.file.clone(),
                        mesh,
                        primitive: prim.index(),
                        index: i,
                        vertices: n,
                    });
                }
                fv[k] = FaceVertex {
                    position: i,
                    normal: has_n.then_some(i),
                    uv: has_uv.then_some(i),
                };
            }
            faces.push(fv);
        }
        Ok(Mesh {
            source: format!("{} mesh '{name}' primitive {}", self.file, prim.index()),
            positions,
            normals: if has_n { normals } else { Vec::new() },
            uvs: if has_uv { uvs } else { Vec::new() },
            faces,
            groups: Vec::new(),
        })
    }
}
