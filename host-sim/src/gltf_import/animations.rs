//! glTF animations -> the film's tracks (docs/scene-format.md, "glTF animations").
//!
//! Every channel of every animation that moves a node's `translation`, `rotation` or `scale`
//! becomes a track of that node's cluster ([`Target::Cluster`]); all animations play together
//! from the same clock. glTF times are seconds and glTF has no frame rate: key time `t` is
//! frame `t · rate` ([`DEFAULT_RATE`], 24 frames per second), and the film's frames are
//! `floor(t_min · rate) ..= floor(t_max · rate)` over every channel's keys. Interpolation:
//! LINEAR -> linear (slerp for rotations, as glTF asks), STEP -> step, CUBICSPLINE -> smooth
//! (Catmull-Rom through the key values; the file's tangents are not used, and a warning says
//! so). Rotation keys (unit quaternions) are written as the scene format's Euler angles by
//! the same conversion as a node's rest rotation; the film slerps them as quaternions again.
//! Morph-target weights are named in a warning and not imported.

use std::collections::HashMap;

use gltf::accessor::{DataType, Dimensions};
use gltf::animation::util::ReadOutputs;
use gltf::animation::{Interpolation as GltfInterpolation, Property};
use links_core::anim::{
    track_value, Interpolation, Key, Keys, Target, Timeline, Track, TransformProperty, Value,
};
use links_core::desc::{Cluster, Node, Shape};

use super::buffers::check_accessor;
use super::error::GltfError;
use super::transform::{
    apply_point, matrix_to_euler_deg, mul, quat_to_matrix, transform_matrix, Mat4, IDENTITY,
};
use super::warning::Warning;
use super::Importer;

/// Frames per second of an imported animation (glTF times are seconds; glTF has no rate).
pub const DEFAULT_RATE: f64 = 24.0;
/// The most frames an imported animation may span.
pub const MAX_FRAMES: f64 = 1_000_000.0;
/// Frames sampled (evenly, and the last) for the box the animation sweeps.
pub const SWEEP_SAMPLES: usize = 48;

/// The imported animation: its frames and tracks (no tracks: a still, [`Timeline::STILL`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Animation {
    pub timeline: Timeline,
    pub tracks: Vec<Track>,
}

/// glTF node index -> the paths (child indices from the root) of the clusters made from it.
pub type NodePaths = HashMap<usize, Vec<Vec<u32>>>;

/// The clusters made from `scene`'s nodes under `root` (as [`Importer::node`] built them:
/// a node's cluster holds its mesh's shapes, then its children's clusters in order).
pub fn node_paths(scene: &gltf::Scene<'_>, root: &Cluster) -> NodePaths {
    let mut paths = NodePaths::new();
    for (node, (k, _)) in scene.nodes().zip(clusters(root)) {
        walk(&node, root, vec![k], &mut paths);
    }
    paths
}

/// The child clusters of `c` with their indices among its children.
fn clusters(c: &Cluster) -> impl Iterator<Item = (u32, &Cluster)> {
    c.children.iter().enumerate().filter_map(|(i, n)| match n {
        Node::Cluster(sub) => Some((u32::try_from(i).ok()?, sub)),
        Node::Shape(_) => None,
    })
}

fn walk(node: &gltf::Node<'_>, root: &Cluster, path: Vec<u32>, paths: &mut NodePaths) {
    let Some(here) = cluster_at(root, &path) else {
        return;
    };
    for (child, (k, _)) in node.children().zip(clusters(here)) {
        let mut p = path.clone();
        p.push(k);
        walk(&child, root, p, paths);
    }
    paths.entry(node.index()).or_default().push(path);
}

fn cluster_at<'c>(root: &'c Cluster, path: &[u32]) -> Option<&'c Cluster> {
    let mut c = root;
    for &i in path {
        match c.children.get(i as usize)? {
            Node::Cluster(sub) => c = sub,
            Node::Shape(_) => return None,
        }
    }
    Some(c)
}

/// The world box of every mesh over the animation (`None` without tracks): the default
/// camera frames it, so what moves stays in the picture. Sampled at [`SWEEP_SAMPLES`] frames
/// spread evenly over the film, and its last, with each mesh's local box corners.
pub fn swept_bounds(root: &Cluster, anim: &Animation) -> Option<([f64; 3], [f64; 3])> {
    if anim.tracks.is_empty() {
        return None;
    }
    let frames = anim.timeline.frames();
    let step = (frames.len().div_ceil(SWEEP_SAMPLES)).max(1);
    let last = frames.end.saturating_sub(1);
    let mut posed = root.clone();
    let mut bounds = None;
    for f in frames.step_by(step).chain(std::iter::once(last)) {
        for track in &anim.tracks {
            let value = track_value(track, f64::from(f));
            if let (Target::Cluster { path, property }, Some(Value::Vector(v))) =
                (&track.target, value)
            {
                if let Some(t) = cluster_at_mut(&mut posed, path).map(|c| &mut c.transform) {
                    match property {
                        TransformProperty::Translate => t.translate = v,
                        TransformProperty::Rotate => t.rotate_deg = v,
                        TransformProperty::Scale => t.scale = v,
                    }
                }
            }
        }
        include_meshes(&posed, &IDENTITY, &mut bounds);
    }
    bounds
}

fn cluster_at_mut<'c>(root: &'c mut Cluster, path: &[u32]) -> Option<&'c mut Cluster> {
    let mut c = root;
    for &i in path {
        match c.children.get_mut(i as usize)? {
            Node::Cluster(sub) => c = sub,
            Node::Shape(_) => return None,
        }
    }
    Some(c)
}

/// Grows `bounds` by the world corners of every mesh's local box under `c`.
fn include_meshes(c: &Cluster, parent: &Mat4, bounds: &mut Option<([f64; 3], [f64; 3])>) {
    let here = mul(parent, &transform_matrix(&c.transform));
    for child in &c.children {
        match child {
            Node::Cluster(sub) => include_meshes(sub, &here, bounds),
            Node::Shape(Shape::Mesh { mesh, .. }) => {
                let Some(&first) = mesh.positions.first() else {
                    continue;
                };
                let (mut lo, mut hi) = (first, first);
                for p in &mesh.positions {
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
                for corner in 0..8 {
                    let p = [0, 1, 2].map(|k| if corner >> k & 1 == 0 { lo[k] } else { hi[k] });
                    let w = apply_point(&here, p);
                    let (blo, bhi) = bounds.get_or_insert((w, w));
                    for k in 0..3 {
                        blo[k] = blo[k].min(w[k]);
                        bhi[k] = bhi[k].max(w[k]);
                    }
                }
            }
            Node::Shape(_) => {}
        }
    }
}

/// One channel read: its property, interpolation and keys in seconds.
struct ChannelKeys {
    property: TransformProperty,
    interpolation: Interpolation,
    times: Vec<f64>,
    values: Vec<[f64; 3]>,
}

impl Importer<'_> {
    /// Every animation's TRS channels as tracks of the clusters in `paths`.
    pub(super) fn animations(&mut self, paths: &NodePaths) -> Result<Animation, GltfError> {
        let mut tracks = Vec::new();
        let mut seen: HashMap<(usize, u8), String> = HashMap::new();
        let (mut t_min, mut t_max) = (f64::INFINITY, f64::NEG_INFINITY);
        for anim in self.doc.animations() {
            for channel in anim.channels() {
                let at = format!("animations[{}].channels[{}]", anim.index(), channel.index());
                let Some(keys) = self.channel_keys(&channel, &at)? else {
                    continue;
                };
                let node = channel.target().node();
                let Some(node_paths) = paths.get(&node.index()) else {
                    self.warnings.push(Warning::AnimationTarget {
                        channel: at,
                        message: format!("nodes[{}] is not in the imported scene", node.index()),
                    });
                    continue;
                };
                if let Some(first) = seen.insert((node.index(), keys.property as u8), at.clone()) {
                    self.warnings.push(Warning::AnimationTarget {
                        message: format!("{first} already moves this property; this one ignored"),
                        channel: at,
                    });
                    continue;
                }
                if node.camera().is_some() || node.light().is_some() {
                    self.warnings.push(Warning::AnimationTarget {
                        channel: at.clone(),
                        message: "the node's camera or light stays where it is at rest".into(),
                    });
                }
                t_min = t_min.min(keys.times[0]);
                t_max = t_max.max(keys.times[keys.times.len() - 1]);
                for path in node_paths {
                    tracks.push(track(path.clone(), &keys));
                }
            }
        }
        if tracks.is_empty() {
            return Ok(Animation {
                timeline: Timeline::STILL,
                tracks,
            });
        }
        let timeline = self.timeline(t_min, t_max)?;
        Ok(Animation { timeline, tracks })
    }

    /// Frames `floor(t_min · rate) ..= floor(t_max · rate)`.
    fn timeline(&self, t_min: f64, t_max: f64) -> Result<Timeline, GltfError> {
        let (a, b) = (
            (t_min * DEFAULT_RATE).floor(),
            (t_max * DEFAULT_RATE).floor(),
        );
        if !(a >= 0.0 && b < MAX_FRAMES) {
            return Err(GltfError::TooLarge {
                file: self.file.clone(),
                message: format!(
                    "the animations run from {t_min} s to {t_max} s: at {DEFAULT_RATE} frames \
                     per second that is outside frames 0..{MAX_FRAMES}"
                ),
            });
        }
        Ok(Timeline {
            start: a as u32,
            end: b as u32 + 1,
            rate: DEFAULT_RATE,
        })
    }

    /// A channel's keys, checked; `None` (with a warning) for morph-target weights.
    fn channel_keys(
        &mut self,
        channel: &gltf::animation::Channel<'_>,
        at: &str,
    ) -> Result<Option<ChannelKeys>, GltfError> {
        let property = match channel.target().property() {
            Property::Translation => TransformProperty::Translate,
            Property::Rotation => TransformProperty::Rotate,
            Property::Scale => TransformProperty::Scale,
            Property::MorphTargetWeights => {
                self.warnings.push(Warning::AnimationTarget {
                    channel: at.to_string(),
                    message: "morph-target weights are not imported".into(),
                });
                return Ok(None);
            }
        };
        let sampler = channel.sampler();
        let interpolation = match sampler.interpolation() {
            GltfInterpolation::Linear => Interpolation::Linear,
            GltfInterpolation::Step => Interpolation::Step,
            GltfInterpolation::CubicSpline => {
                self.warnings.push(Warning::CubicSpline {
                    channel: at.to_string(),
                });
                Interpolation::Smooth
            }
        };
        let times = self.read_times(channel, at)?;
        let per_key = if interpolation == Interpolation::Smooth {
            3
        } else {
            1
        };
        let all = self.read_values(channel, property, at)?;
        if all.len() != times.len() * per_key {
            return Err(self.bad(
                at,
                format!(
                    "the sampler has {} input times and {} outputs; {} interpolation needs {}",
                    times.len(),
                    all.len(),
                    sampler_name(sampler.interpolation()),
                    times.len() * per_key
                ),
            ));
        }
        // CUBICSPLINE outputs are (in-tangent, value, out-tangent) per key: keep the values.
        let values = all.into_iter().skip(per_key / 2).step_by(per_key).collect();
        Ok(Some(ChannelKeys {
            property,
            interpolation,
            times,
            values,
        }))
    }

    /// The sampler's input: scalar floats, finite and strictly increasing, at least one.
    fn read_times(
        &self,
        channel: &gltf::animation::Channel<'_>,
        at: &str,
    ) -> Result<Vec<f64>, GltfError> {
        let input = channel.sampler().input();
        check_accessor(&input, &self.buffers, &self.file)?;
        if input.data_type() != DataType::F32 || input.dimensions() != Dimensions::Scalar {
            return Err(self.bad(at, "the sampler's input must be SCALAR FLOAT times".into()));
        }
        let buffers = &self.buffers;
        let reader = channel.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let times: Vec<f64> = reader
            .read_inputs()
            .ok_or_else(|| self.bad(at, "the sampler's input has no data".into()))?
            .map(f64::from)
            .collect();
        if times.is_empty()
            || times.iter().any(|t| !t.is_finite() || *t < 0.0)
            || times.windows(2).any(|w| w[0] >= w[1])
        {
            return Err(self.bad(
                at,
                "the sampler's input times must be finite, >= 0 and strictly increasing".into(),
            ));
        }
        Ok(times)
    }

    /// The sampler's output as 3-vectors (rotations as Euler angles in degrees).
    fn read_values(
        &self,
        channel: &gltf::animation::Channel<'_>,
        property: TransformProperty,
        at: &str,
    ) -> Result<Vec<[f64; 3]>, GltfError> {
        let output = channel.sampler().output();
        check_accessor(&output, &self.buffers, &self.file)?;
        let (dims, types): (Dimensions, &[DataType]) = match property {
            TransformProperty::Rotate => (
                Dimensions::Vec4,
                &[
                    DataType::F32,
                    DataType::I8,
                    DataType::U8,
                    DataType::I16,
                    DataType::U16,
                ],
            ),
            _ => (Dimensions::Vec3, &[DataType::F32]),
        };
        if output.dimensions() != dims || !types.contains(&output.data_type()) {
            return Err(self.bad(
                at,
                format!(
                    "the sampler's output is {:?} {:?}; a {property:?} channel needs {dims:?} \
                     of {types:?}",
                    output.dimensions(),
                    output.data_type()
                ),
            ));
        }
        let buffers = &self.buffers;
        let reader = channel.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let values: Vec<[f64; 3]> = match reader.read_outputs() {
            Some(ReadOutputs::Translations(it)) | Some(ReadOutputs::Scales(it)) => {
                it.map(|v| v.map(f64::from)).collect()
            }
            Some(ReadOutputs::Rotations(r)) => r
                .into_f32()
                .map(|q| matrix_to_euler_deg(&quat_to_matrix(q.map(f64::from))))
                .collect(),
            _ => return Err(self.bad(at, "the sampler's output has no data".into())),
        };
        if values.iter().flatten().any(|x| !x.is_finite()) {
            return Err(self.bad(at, "the sampler's output is not finite".into()));
        }
        Ok(values)
    }

    fn bad(&self, at: &str, message: String) -> GltfError {
        GltfError::Animation {
            file: self.file.clone(),
            path: at.to_string(),
            message,
        }
    }
}

fn sampler_name(i: GltfInterpolation) -> &'static str {
    match i {
        GltfInterpolation::Linear => "LINEAR",
        GltfInterpolation::Step => "STEP",
        GltfInterpolation::CubicSpline => "CUBICSPLINE",
    }
}

/// The track of `keys` on the cluster at `path`; key time `t` s is frame `t · rate`.
fn track(path: Vec<u32>, keys: &ChannelKeys) -> Track {
    let k = keys
        .times
        .iter()
        .zip(&keys.values)
        .map(|(&t, &value)| Key {
            frame: t * DEFAULT_RATE,
            value,
        })
        .collect();
    Track {
        target: Target::Cluster {
            path,
            property: keys.property,
        },
        interpolation: keys.interpolation,
        keys: Keys::Vector(k),
    }
}
