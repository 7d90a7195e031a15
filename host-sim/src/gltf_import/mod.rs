//! glTF 2.0 import (`.gltf` with embedded or external buffers, `.glb`) -> [`SceneDesc`].
//!
//! The node hierarchy becomes the cluster tree (one cluster per node, its TRS or decomposed
//! matrix as the cluster's [`links_core::desc::Transform`]), each TRIANGLES primitive a
//! [`links_core::desc::Shape::Mesh`], materials the eq. 2.1 terms by the rule in
//! [`materials`], the first perspective camera the view, KHR_lights_punctual the lights.
//! Whatever is not imported is named in a [`Warning`]; a malformed file is a [`GltfError`]
//! naming the file and the JSON path or index. See docs/scene-format.md, "glTF import".

mod animations;
mod base64;
mod buffers;
mod error;
mod materials;
mod meshes;
mod nodes;
mod transform;
mod view;
mod warning;

use std::collections::HashMap;
use std::path::Path;

use links_core::anim::{AnimError, Film};
use links_core::desc::{Cluster, Material, SceneDesc, Texture, TransparencyMode};

use crate::limits::{read_bounded, MAX_MESH_BYTES};

pub use animations::{Animation, DEFAULT_RATE};
pub use error::GltfError;
pub use materials::{eq21_terms, Pbr};
pub use transform::{
    euler_deg_to_matrix, matrix_to_euler_deg, quat_to_matrix, transform_matrix, Mat3, Mat4,
};
pub use warning::Warning;

/// Extensions whose content is imported (or, for the two material ones, read by the rule).
const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_ior",
    "KHR_materials_transmission",
];

/// The image width when the camera's aspect ratio sets the height; and the default size.
pub const DEFAULT_WIDTH: u32 = 512;
pub const DEFAULT_HEIGHT: u32 = 480;

/// An imported scene (its nodes at rest), its animation and what could not be carried over.
#[derive(Debug)]
pub struct Imported {
    pub scene: SceneDesc,
    /// The TRS channels as tracks ([`links_core::anim::Timeline::STILL`] and no tracks without animations).
    pub animation: Animation,
    pub warnings: Vec<Warning>,
}

impl Imported {
    /// The scene as a film: the animation's frames and tracks (checked again by
    /// [`Film::new`]), or the still scene's one frame.
    pub fn film(&self) -> Result<Film, AnimError> {
        if self.animation.tracks.is_empty() {
            return Ok(Film::still(self.scene.clone()));
        }
        Film::new(
            self.scene.clone(),
            self.animation.timeline,
            self.animation.tracks.clone(),
        )
    }
}

/// Does `path` name a glTF file (`.gltf` or `.glb`, any case)?
pub fn is_gltf_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"))
}

/// Imports the glTF or GLB file at `path` (read bounded; buffers and images relative to it).
pub fn import(path: &Path) -> Result<Imported, GltfError> {
    let bytes = read_bounded(path, MAX_MESH_BYTES, "glTF file").map_err(GltfError::Read)?;
    let base_dir = path.parent().unwrap_or_else(|| Path::new(""));
    import_slice(&bytes, &path.display().to_string(), base_dir)
}

/// Imports glTF/GLB `bytes`; `file` names it in messages, `base_dir` resolves relative URIs.
pub fn import_slice(bytes: &[u8], file: &str, base_dir: &Path) -> Result<Imported, GltfError> {
    let parse_err = |e: gltf::Error| GltfError::Parse {
        file: file.to_string(),
        message: e.to_string(),
    };
    let gltf = gltf::Gltf::from_slice_without_validation(bytes).map_err(parse_err)?;
    let json = gltf.document.into_json();
    if let Some(name) = json
        .extensions_required
        .iter()
        .find(|n| !SUPPORTED_EXTENSIONS.contains(&n.as_str()))
    {
        return Err(GltfError::RequiredExtension {
            file: file.to_string(),
            name: name.clone(),
        });
    }
    let doc = gltf::Document::from_json(json).map_err(|e| validation_error(e, file))?;
    let buffers = buffers::load_buffers(&doc, gltf.blob, file, base_dir)?;
    let importer = Importer {
        file: file.to_string(),
        base_dir,
        doc: &doc,
        buffers,
        warnings: Vec::new(),
        materials: Vec::new(),
        material_of: HashMap::new(),
        textures: Vec::new(),
        texture_of: HashMap::new(),
        visits: 0,
    };
    importer.run()
}

fn validation_error(e: gltf::Error, file: &str) -> GltfError {
    match e {
        gltf::Error::Validation(list) => {
            let (path, message) = list
                .first()
                .map(|(p, e)| (p.to_string(), e.to_string()))
                .unwrap_or_default();
            let more = list.len().saturating_sub(1);
            GltfError::Invalid {
                file: file.to_string(),
                path,
                message: if more > 0 {
                    format!("{message} (and {more} more problems)")
                } else {
                    message
                },
            }
        }
        other => GltfError::Parse {
            file: file.to_string(),
            message: other.to_string(),
        },
    }
}

/// The state of one import.
pub(crate) struct Importer<'a> {
    file: String,
    base_dir: &'a Path,
    doc: &'a gltf::Document,
    buffers: Vec<Vec<u8>>,
    warnings: Vec<Warning>,
    materials: Vec<Material>,
    /// glTF material index (None: glTF's default material) -> ours.
    material_of: HashMap<Option<usize>, u32>,
    textures: Vec<Texture>,
    /// glTF image index -> ours (None: not decodable, factor colour only).
    texture_of: HashMap<usize, Option<u32>>,
    /// Nodes expanded so far (a node used by several parents counts each time).
    visits: usize,
}

impl Importer<'_> {
    fn run(mut self) -> Result<Imported, GltfError> {
        self.warn_document();
        let scene = self
            .doc
            .default_scene()
            .or_else(|| self.doc.scenes().next())
            .ok_or_else(|| GltfError::Empty {
                file: self.file.clone(),
                message: "the file has no scene".into(),
            })?;
        let count = self.doc.scenes().count();
        if count > 1 {
            self.warnings.push(Warning::OtherScenes {
                imported: scene.index(),
                count,
            });
        }
        let mut root = Cluster {
            name: scene
                .name()
                .map_or_else(|| format!("scene {}", scene.index()), str::to_string),
            ..Cluster::default()
        };
        let mut world = nodes::WorldInfo::default();
        for node in scene.nodes() {
            let child = self.node(&node, &transform::IDENTITY, 0, &mut world)?;
            root.children.push(links_core::desc::Node::Cluster(child));
        }
        if world.bounds.is_none() {
            return Err(GltfError::Empty {
                file: self.file.clone(),
                message: "the scene has no triangles".into(),
            });
        }
        let animation = self.animations(&animations::node_paths(&scene, &root))?;
        if let Some((lo, hi)) = animations::swept_bounds(&root, &animation) {
            world.include(lo);
            world.include(hi);
        }
        let (camera, width, height) = self.camera(&world);
        let lights = self.lights(&world, &camera);
        Ok(Imported {
            animation,
            scene: SceneDesc {
                camera,
                width,
                height,
                background: [0.0; 3],
                ambient: [0.1; 3],
                max_depth: 5,
                transparency: TransparencyMode::Refractive,
                materials: self.materials,
                textures: self.textures,
                lights,
                root,
            },
            warnings: self.warnings,
        })
    }

    /// Warnings about the document as a whole: extensions used but ignored.
    fn warn_document(&mut self) {
        for name in self.doc.extensions_used() {
            if !SUPPORTED_EXTENSIONS.contains(&name) {
                self.warnings.push(Warning::Extension {
                    name: name.to_string(),
                });
            }
        }
    }

    /// Our index of glTF material `mat`, converting it (and its base-colour texture) once.
    fn material_index(&mut self, mat: &gltf::Material<'_>) -> Result<u32, GltfError> {
        if let Some(&i) = self.material_of.get(&mat.index()) {
            return Ok(i);
        }
        let name = match (mat.name(), mat.index()) {
            (Some(n), _) => n.to_string(),
            (None, Some(i)) => format!("material {i}"),
            (None, None) => "default".to_string(),
        };
        let pbr = materials::read_pbr(mat, &name, &mut self.warnings);
        let mut material = materials::eq21_terms(&name, &pbr);
        if let Some(info) = mat.pbr_metallic_roughness().base_color_texture() {
            if info.tex_coord() != 0 {
                self.warnings.push(Warning::MaterialFeature {
                    material: name.clone(),
                    feature: format!("baseColorTexture on TEXCOORD_{}", info.tex_coord()),
                });
            } else if let Some(t) = self.texture_index(&info.texture().source())? {
                material.map = Some(materials::diffuse_map(t));
            }
        }
        let i = u32::try_from(self.materials.len()).unwrap_or(u32::MAX);
        self.materials.push(material);
        self.material_of.insert(mat.index(), i);
        Ok(i)
    }

    /// Our texture of glTF image `image` if it is a PNG (decoded once), else a warning.
    fn texture_index(&mut self, image: &gltf::Image<'_>) -> Result<Option<u32>, GltfError> {
        if let Some(&t) = self.texture_of.get(&image.index()) {
            return Ok(t);
        }
        let idx = image.index();
        let bytes = buffers::image_bytes(image.source(), &self.buffers, self.base_dir).map_err(
            |e| match e {
                buffers::UriError::Read(r) => GltfError::Read(r),
                buffers::UriError::Malformed(message) => GltfError::Image {
                    file: self.file.clone(),
                    image: idx,
                    message,
                },
            },
        )?;
        let t =
            if materials::is_png(&bytes) {
                let name = image
                    .name()
                    .map_or_else(|| format!("image {idx}"), str::to_string);
                let tex = crate::scene_file::texture::decode_png(&bytes, &self.file, &name)
                    .map_err(|e| GltfError::Image {
                        file: self.file.clone(),
                        image: idx,
                        message: e.to_string(),
                    })?;
                self.textures.push(tex);
                Some(u32::try_from(self.textures.len() - 1).unwrap_or(u32::MAX))
            } else {
                let mime = match image.source() {
                    gltf::image::Source::View { mime_type, .. } => mime_type.to_string(),
                    gltf::image::Source::Uri { mime_type, .. } => {
                        mime_type.unwrap_or("not PNG").to_string()
                    }
                };
                self.warnings.push(Warning::ImageType { image: idx, mime });
                None
            };
        self.texture_of.insert(idx, t);
        Ok(t)
    }
}

#[cfg(test)]
mod animations_tests;
#[cfg(test)]
mod tests;
