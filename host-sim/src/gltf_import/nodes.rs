//! The node hierarchy -> the cluster tree; on the way, world matrices for the camera, the
//! lights and the scene's bounding box.

use links_core::desc::{Cluster, Node, Shape};

use super::error::GltfError;
use super::transform::{self, Mat4};
use super::warning::Warning;
use super::Importer;

/// Deepest node nesting imported (the scene format's cluster limit).
pub const MAX_DEPTH: usize = 50;
/// Most node expansions (a node reached through several parents counts each time).
pub const MAX_NODE_VISITS: usize = 100_000;

/// A perspective camera found in the tree.
#[derive(Clone, Debug)]
pub struct CameraFound {
    pub name: String,
    pub world: Mat4,
    pub yfov: f64,
    pub aspect: Option<f64>,
}

/// A KHR_lights_punctual light placed by its node.
#[derive(Clone, Debug)]
pub struct LightFound {
    pub world: Mat4,
    pub color: [f32; 3],
    pub intensity: f32,
    pub kind: LightKind,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    Directional,
    Point,
    Spot { inner: f64, outer: f64 },
}

/// What the walk learns about the world.
#[derive(Debug, Default)]
pub struct WorldInfo {
    /// World-space bounding box of every imported vertex.
    pub bounds: Option<([f64; 3], [f64; 3])>,
    pub camera: Option<CameraFound>,
    pub lights: Vec<LightFound>,
}

impl WorldInfo {
    pub(super) fn include(&mut self, p: [f64; 3]) {
        let (lo, hi) = self.bounds.get_or_insert((p, p));
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
}

impl Importer<'_> {
    /// Node `node` under a parent whose world matrix is `parent`, as a cluster.
    pub(super) fn node(
        &mut self,
        node: &gltf::Node<'_>,
        parent: &Mat4,
        depth: usize,
        world: &mut WorldInfo,
    ) -> Result<Cluster, GltfError> {
        self.visits += 1;
        if depth >= MAX_DEPTH || self.visits > MAX_NODE_VISITS {
            return Err(GltfError::TooLarge {
                file: self.file.clone(),
                message: format!(
                    "nodes[{}]: the node graph is nested deeper than {MAX_DEPTH} levels or \
                     expands to more than {MAX_NODE_VISITS} nodes",
                    node.index()
                ),
            });
        }
        let name = node
            .name()
            .map_or_else(|| format!("node {}", node.index()), str::to_string);
        let local = transform::from_f32(node.transform().matrix());
        let cluster_transform = match node.transform() {
            gltf::scene::Transform::Decomposed {
                translation,
                rotation,
                scale,
            } => transform::from_trs(translation, rotation, scale),
            gltf::scene::Transform::Matrix { .. } => {
                let (t, sheared) = transform::decompose(&local);
                if sheared {
                    self.warnings.push(Warning::Shear { node: name.clone() });
                }
                t
            }
        };
        let here = transform::mul(parent, &local);
        if node.skin().is_some() {
            self.warnings.push(Warning::Skin { node: name.clone() });
        }
        self.note_camera_and_light(node, &name, &here, world);
        let mut children = Vec::new();
        if let Some(mesh) = node.mesh() {
            for shape in self.mesh_shapes(&mesh)? {
                if let Shape::Mesh { mesh, .. } = &shape {
                    for &p in &mesh.positions {
                        world.include(transform::apply_point(&here, p));
                    }
                }
                children.push(Node::Shape(shape));
            }
        }
        for child in node.children() {
            let c = self.node(&child, &here, depth + 1, world)?;
            children.push(Node::Cluster(c));
        }
        Ok(Cluster {
            name,
            transform: cluster_transform,
            children,
        })
    }

    fn note_camera_and_light(
        &mut self,
        node: &gltf::Node<'_>,
        name: &str,
        here: &Mat4,
        world: &mut WorldInfo,
    ) {
        if let Some(cam) = node.camera() {
            let cam_name = cam.name().unwrap_or(name).to_string();
            match cam.projection() {
                gltf::camera::Projection::Perspective(p) if world.camera.is_none() => {
                    world.camera = Some(CameraFound {
                        name: cam_name,
                        world: *here,
                        yfov: f64::from(p.yfov()),
                        aspect: p.aspect_ratio().map(f64::from),
                    });
                }
                gltf::camera::Projection::Perspective(_) => {}
                gltf::camera::Projection::Orthographic(_) => self.warnings.push(Warning::Camera {
                    camera: cam_name,
                    message: "orthographic cameras are not supported; skipped".into(),
                }),
            }
        }
        if let Some(light) = node.light() {
            use gltf::khr_lights_punctual::Kind;
            if light.range().is_some() {
                let light_name = light.name().unwrap_or(name).to_string();
                self.warnings
                    .push(Warning::LightRange { light: light_name });
            }
            let kind = match light.kind() {
                Kind::Directional => LightKind::Directional,
                Kind::Point => LightKind::Point,
                Kind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } => LightKind::Spot {
                    inner: f64::from(inner_cone_angle),
                    outer: f64::from(outer_cone_angle),
                },
            };
            world.lights.push(LightFound {
                world: *here,
                color: light.color(),
                intensity: light.intensity(),
                kind,
            });
        }
    }
}
