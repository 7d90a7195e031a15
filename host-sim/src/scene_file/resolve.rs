//! From the parsed file to [`desc::SceneDesc`]: names -> indices, meshes and textures loaded.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::limits::{read_bounded, ReadError, MAX_MESH_BYTES, MAX_TEXTURE_BYTES};

use links_core::anim::Film;
use links_core::desc;

use super::error::SceneError;
use super::format::{ClusterFile, NodeFile, Ref, SceneFile, REPLAY_MARK};
use super::tracks::{edge_tracks, Names, TrackScope};
use super::{obj, parse_file, texture};

pub(super) struct Resolver<'a> {
    text: &'a str,
    file: &'a str,
    base_dir: &'a Path,
    materials: Vec<desc::Material>,
    material_index: HashMap<String, u32>,
    /// Index of the material used by shapes that name none, once needed.
    default_material: Option<u32>,
    texture_index: HashMap<String, u32>,
    meshes: HashMap<PathBuf, desc::Mesh>,
    /// Clusters and named Blobs, for tracks.
    names: Names,
    /// Per material: whether `specular_edge` and `reflect_edge` were left out (they follow).
    edge_follows: Vec<(bool, bool)>,
}

impl<'a> Resolver<'a> {
    pub(super) fn new(text: &'a str, file: &'a str, base_dir: &'a Path) -> Self {
        Self {
            text,
            file,
            base_dir,
            materials: Vec::new(),
            material_index: HashMap::new(),
            default_material: None,
            texture_index: HashMap::new(),
            meshes: HashMap::new(),
            names: Names::default(),
            edge_follows: Vec::new(),
        }
    }

    /// Line and column of `r` in the scene text, found by replaying the parse with `r` primed
    /// to fail (see [`Ref`]).
    fn locate(&self, id: u32) -> (usize, usize) {
        match parse_file(self.text, self.file, Some(id)) {
            Err(SceneError::Invalid {
                line, col, message, ..
            }) if message == REPLAY_MARK => (line, col),
            // Unreachable: the replay reads the same text the same way.
            _ => (0, 0),
        }
    }

    fn invalid_at(&self, r: &Ref, message: String) -> SceneError {
        self.invalid_at_id(r.id, message)
    }

    /// An error at the located value numbered `id` (a [`Ref`] or a `Located`).
    fn invalid_at_id(&self, id: u32, message: String) -> SceneError {
        let (line, col) = self.locate(id);
        SceneError::Invalid {
            file: self.file.to_string(),
            line,
            col,
            message,
        }
    }

    fn asset_error(&self, r: &Ref, kind: &'static str, path: PathBuf, e: ReadError) -> SceneError {
        let (line, col) = self.locate(r.id);
        SceneError::Asset {
            file: self.file.to_string(),
            line,
            col,
            kind,
            path,
            source: Box::new(e),
        }
    }

    /// The film: the scene as written, its frames and its tracks (a still scene without
    /// `frames` is the film of one frame, 0..1).
    pub(super) fn film(mut self, f: SceneFile) -> Result<Film, SceneError> {
        let textures = self.textures(f.textures.0)?;
        for (name, m) in f.materials.0 {
            let map = match m.map {
                None => None,
                Some(map) => Some(desc::TextureMap {
                    texture: self.texture(&map.texture)?,
                    target: map.target.into(),
                    scale: map.scale,
                }),
            };
            let index = self.materials.len() as u32;
            self.material_index.insert(name.clone(), index);
            self.edge_follows
                .push((m.specular_edge.is_none(), m.reflect_edge.is_none()));
            self.materials.push(desc::Material {
                name,
                diffuse: m.diffuse,
                specular: m.specular,
                specular_edge: m.specular_edge.map_or(m.specular, |c| c.0),
                shininess: m.shininess,
                reflect: m.reflect,
                reflect_edge: m.reflect_edge.map_or(m.reflect, |c| c.0),
                transmit: m.transmit,
                ior: m.ior,
                ambient: m.ambient.map(|a| a.0),
                map,
            });
        }
        let root = self.cluster(f.root, None, &mut Vec::new())?;
        let scene = desc::SceneDesc {
            camera: f.camera.0,
            width: f.image.width,
            height: f.image.height,
            background: f.background,
            ambient: f.ambient,
            max_depth: f.max_depth,
            transparency: f.transparency.into(),
            materials: std::mem::take(&mut self.materials),
            textures,
            lights: f.lights.into_iter().map(|l| l.0).collect(),
            root,
        };
        let timeline = f.frames.map(|fr| fr.0);
        let at = |id, message| self.invalid_at_id(id, message);
        let scope = TrackScope {
            timeline,
            names: &self.names,
            materials: &scene.materials,
            lights: &scene.lights,
            at: &at,
        };
        let mut tracks = scope.resolve(f.tracks)?;
        edge_tracks(&mut tracks, &self.edge_follows);
        let Some(timeline) = timeline else {
            return Ok(Film::still(scene));
        };
        // The loader checked what Film::new checks; its refusal would be a loader bug.
        Film::new(scene, timeline, tracks).map_err(|e| SceneError::Invalid {
            file: self.file.to_string(),
            line: 1,
            col: 1,
            message: format!("internal error: the film is inconsistent: {e}"),
        })
    }

    fn textures(&mut self, list: Vec<(String, Ref)>) -> Result<Vec<desc::Texture>, SceneError> {
        let mut out = Vec::with_capacity(list.len());
        for (name, path) in list {
            let full = self.base_dir.join(&path.text);
            let bytes = read_bounded(&full, MAX_TEXTURE_BYTES, "texture file")
                .map_err(|e| self.asset_error(&path, "texture", full.clone(), e))?;
            let tex = texture::decode_png(&bytes, &full.display().to_string(), &name)?;
            self.texture_index.insert(name, out.len() as u32);
            out.push(tex);
        }
        Ok(out)
    }

    fn texture(&self, r: &Ref) -> Result<u32, SceneError> {
        self.texture_index.get(&r.text).copied().ok_or_else(|| {
            let names = in_order(&self.texture_index);
            self.invalid_at(
                r,
                format!(
                    "unknown texture \"{}\"; {}",
                    r.text,
                    known("textures", &names)
                ),
            )
        })
    }

    fn material(&self, r: &Ref) -> Result<u32, SceneError> {
        self.material_index.get(&r.text).copied().ok_or_else(|| {
            let names = in_order(&self.material_index);
            self.invalid_at(
                r,
                format!(
                    "unknown material \"{}\"; {}",
                    r.text,
                    known("materials", &names)
                ),
            )
        })
    }

    /// The material for shapes with none named anywhere above them: the scene's own "default"
    /// if it defines one, else [`desc::Material::default`] appended to the list.
    fn default_material(&mut self) -> u32 {
        if let Some(&i) = self.material_index.get("default") {
            return i;
        }
        *self.default_material.get_or_insert_with(|| {
            self.materials.push(desc::Material::default());
            (self.materials.len() - 1) as u32
        })
    }

    /// The cluster at `path` (child indices from the root), its name and its named Blobs
    /// recorded for tracks.
    fn cluster(
        &mut self,
        c: ClusterFile,
        inherited: Option<u32>,
        path: &mut Vec<u32>,
    ) -> Result<desc::Cluster, SceneError> {
        let inherited = match &c.material {
            Some(r) => Some(self.material(r)?),
            None => inherited,
        };
        if !c.name.is_empty() {
            let paths = self.names.clusters.entry(c.name.clone()).or_default();
            paths.push(path.clone());
        }
        let mut children = Vec::with_capacity(c.children.len());
        for (i, child) in c.children.into_iter().enumerate() {
            path.push(i as u32);
            children.push(match child {
                NodeFile::Cluster(sub) => desc::Node::Cluster(self.cluster(sub, inherited, path)?),
                NodeFile::Shape {
                    mut shape,
                    material,
                    name,
                } => {
                    if let (false, desc::Shape::Blobs { balls, .. }) = (name.is_empty(), &shape) {
                        let found = (path.clone(), balls.len());
                        self.names.blobs.entry(name).or_default().push(found);
                    }
                    set_material(
                        &mut shape,
                        self.shape_material(material.as_ref(), inherited)?,
                    );
                    desc::Node::Shape(shape)
                }
                NodeFile::Mesh {
                    file,
                    smooth,
                    material,
                } => {
                    let material = self.shape_material(material.as_ref(), inherited)?;
                    let mesh = self.mesh(&file)?;
                    desc::Node::Shape(desc::Shape::Mesh {
                        mesh,
                        material,
                        smooth,
                    })
                }
            });
            path.pop();
        }
        Ok(desc::Cluster {
            name: c.name,
            transform: c.transform.0,
            children,
        })
    }

    fn shape_material(
        &mut self,
        own: Option<&Ref>,
        inherited: Option<u32>,
    ) -> Result<u32, SceneError> {
        match (own, inherited) {
            (Some(r), _) => self.material(r),
            (None, Some(i)) => Ok(i),
            (None, None) => Ok(self.default_material()),
        }
    }

    fn mesh(&mut self, r: &Ref) -> Result<desc::Mesh, SceneError> {
        let full = self.base_dir.join(&r.text);
        if let Some(m) = self.meshes.get(&full) {
            return Ok(m.clone());
        }
        let bytes = read_bounded(&full, MAX_MESH_BYTES, "mesh file")
            .map_err(|e| self.asset_error(r, "mesh", full.clone(), e))?;
        let shown = full.display().to_string();
        let text = String::from_utf8(bytes).map_err(|e| {
            let valid = &e.as_bytes()[..e.utf8_error().valid_up_to()];
            SceneError::Obj {
                file: shown.clone(),
                line: Some(1 + valid.iter().filter(|&&b| b == b'\n').count()),
                col: None,
                message: "not a text file (invalid UTF-8)".to_string(),
            }
        })?;
        let mesh = obj::parse_obj(&text, &shown, &r.text)?;
        self.meshes.insert(full, mesh.clone());
        Ok(mesh)
    }
}

fn set_material(shape: &mut desc::Shape, index: u32) {
    match shape {
        desc::Shape::Triangle { material, .. }
        | desc::Shape::Mesh { material, .. }
        | desc::Shape::Ellipsoid { material, .. }
        | desc::Shape::Box { material, .. }
        | desc::Shape::Blobs { material, .. } => *material = index,
    }
}

/// The names of an index map, in index (= file) order.
fn in_order(index: &HashMap<String, u32>) -> Vec<&str> {
    let mut names: Vec<(&str, u32)> = index.iter().map(|(k, &i)| (k.as_str(), i)).collect();
    names.sort_by_key(|&(_, i)| i);
    names.into_iter().map(|(n, _)| n).collect()
}

/// `the scene defines materials "a", "b"` / `the scene defines no textures`.
fn known(kind: &str, names: &[&str]) -> String {
    if names.is_empty() {
        return format!("the scene defines no {kind}");
    }
    let shown: Vec<String> = names.iter().take(12).map(|n| format!("\"{n}\"")).collect();
    let more = if names.len() > shown.len() {
        ", ..."
    } else {
        ""
    };
    format!("the scene defines {kind} {}{more}", shown.join(", "))
}
