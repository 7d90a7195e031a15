//! Films: a still [`SceneDesc`] plus a timeline and keyframed tracks, and the DM's first step
//! for each frame, [`Film::scene_at`]: the still scene with every track's value at that
//! frame written in. Compiling that scene ([`Film::compile_frame`]) is the whole per-frame
//! work of the DM, so a simulator can prepare frame n+1 while frame n renders.
//!
//! - [`interp`]: sampling a track (step, linear, smooth Catmull-Rom), generic over the value.
//! - [`quat`]: rotations as unit quaternions (slerp), to and from the format's Euler angles.
//!
//! Times are in frames: frame `f` is time `f`; the rate (frames per second) only says how
//! fast the film plays. Feature `std` (the DM's side).

pub mod interp;
pub mod quat;

#[cfg(test)]
mod tests;

use core::fmt;
use core::ops::Range;
use std::vec::Vec;

use crate::desc::{Cluster, Light, Node, SceneDesc, Shape};
use crate::dm::{compile, CompileOptions, Compiled, DmError};

use interp::{sample, segment};
pub use interp::{Interpolation, Key};
use quat::Quat;

/// Frames `start..end` (end exclusive) played at `rate` frames per second.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timeline {
    pub start: u32,
    pub end: u32,
    pub rate: f64,
}

impl Timeline {
    /// The timeline of a still scene: the one frame 0..1.
    pub const STILL: Timeline = Timeline {
        start: 0,
        end: 1,
        rate: 24.0,
    };

    pub fn frames(&self) -> Range<u32> {
        self.start..self.end
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraProperty {
    Eye,
    LookAt,
    Up,
    FovY,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransformProperty {
    Translate,
    Rotate,
    Scale,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightProperty {
    /// A point or spot light's `pos`.
    Position,
    /// A directional or spot light's `dir`.
    Direction,
    Color,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaterialProperty {
    Diffuse,
    Specular,
    SpecularEdge,
    Shininess,
    Reflect,
    ReflectEdge,
    Transmit,
    Ior,
    /// The ambient reflection colour `arc` (a material without one gets it at every frame).
    Ambient,
}

/// What a track drives. Clusters and blob groups are found by their child indices from the
/// root (`[]` is the root itself).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Target {
    Camera(CameraProperty),
    Cluster {
        path: Vec<u32>,
        property: TransformProperty,
    },
    Light {
        index: u32,
        property: LightProperty,
    },
    Material {
        index: u32,
        property: MaterialProperty,
    },
    /// The centre of ball `ball` of the Blobs shape at `path`.
    BallCenter {
        path: Vec<u32>,
        ball: u32,
    },
}

/// How a property's values are interpolated and kept valid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueKind {
    /// A position: any value.
    Point,
    /// A direction: normalised after interpolation.
    Direction,
    /// Euler angles: interpolated as unit quaternions.
    Rotation,
    /// A bounded vector or number (scale, colour, coefficient, angle): smooth interpolation
    /// is clamped, per component, between the two keys around the time (no overshoot).
    Bounded,
}

impl Target {
    /// Whether the property is a number (else a 3-vector).
    pub fn is_number(&self) -> bool {
        use MaterialProperty as M;
        matches!(
            self,
            Target::Camera(CameraProperty::FovY)
                | Target::Material {
                    property: M::Specular
                        | M::SpecularEdge
                        | M::Shininess
                        | M::Reflect
                        | M::ReflectEdge
                        | M::Ior,
                    ..
                }
        )
    }

    pub fn kind(&self) -> ValueKind {
        match self {
            Target::Camera(CameraProperty::Eye | CameraProperty::LookAt)
            | Target::Cluster {
                property: TransformProperty::Translate,
                ..
            }
            | Target::Light {
                property: LightProperty::Position,
                ..
            }
            | Target::BallCenter { .. } => ValueKind::Point,
            Target::Camera(CameraProperty::Up)
            | Target::Light {
                property: LightProperty::Direction,
                ..
            } => ValueKind::Direction,
            Target::Cluster {
                property: TransformProperty::Rotate,
                ..
            } => ValueKind::Rotation,
            _ => ValueKind::Bounded,
        }
    }
}

/// A track's keys: numbers or 3-vectors, by the target's property.
#[derive(Clone, Debug, PartialEq)]
pub enum Keys {
    Number(Vec<Key<f64>>),
    Vector(Vec<Key<[f64; 3]>>),
}

impl Keys {
    fn times(&self) -> Vec<f64> {
        match self {
            Keys::Number(k) => k.iter().map(|k| k.frame).collect(),
            Keys::Vector(k) => k.iter().map(|k| k.frame).collect(),
        }
    }
}

/// One keyframed property.
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    pub target: Target,
    pub interpolation: Interpolation,
    pub keys: Keys,
}

/// A track's value at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    Number(f64),
    Vector([f64; 3]),
}

/// Why a film is inconsistent or a frame cannot be made.
#[derive(Clone, Debug, PartialEq)]
pub enum AnimError {
    /// The timeline is empty (`start >= end`) or its rate is not a positive number.
    BadTimeline { start: u32, end: u32, rate: f64 },
    /// Track `track` has no keys, keys out of order, or values of the wrong kind.
    BadKeys { track: usize, why: &'static str },
    /// Track `track` names something the scene does not have (or of the wrong type).
    NoTarget { track: usize },
    /// A frame outside the timeline was asked for.
    FrameOutside { frame: u32, start: u32, end: u32 },
    /// Track `track`'s direction interpolates to zero at `frame` (keys pointing opposite ways).
    ZeroDirection { track: usize, frame: u32 },
}

impl fmt::Display for AnimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AnimError::BadTimeline { start, end, rate } => write!(
                f,
                "frames {start}..{end} at {rate} per second: a film needs start < end and a positive rate"
            ),
            AnimError::BadKeys { track, why } => write!(f, "track {track}: {why}"),
            AnimError::NoTarget { track } => {
                write!(f, "track {track}: its target is not in the scene")
            }
            AnimError::FrameOutside { frame, start, end } => write!(
                f,
                "frame {frame} is outside the film's frames {start}..{end}"
            ),
            AnimError::ZeroDirection { track, frame } => write!(
                f,
                "track {track}: the direction interpolates to zero at frame {frame} \
                 (keys pointing opposite ways); add a key between them"
            ),
        }
    }
}

impl core::error::Error for AnimError {}

/// Why [`Film::compile_frame`] failed.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameError {
    Anim(AnimError),
    Dm { frame: u32, source: DmError },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::Anim(e) => write!(f, "{e}"),
            FrameError::Dm { frame, source } => write!(f, "frame {frame}: {source}"),
        }
    }
}

impl core::error::Error for FrameError {}

/// A scene that moves: the still scene (the values as written), the timeline and the tracks.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    scene: SceneDesc,
    timeline: Timeline,
    tracks: Vec<Track>,
}

impl Film {
    /// A still scene as a film of the one frame 0..1.
    pub fn still(scene: SceneDesc) -> Film {
        Film {
            scene,
            timeline: Timeline::STILL,
            tracks: Vec::new(),
        }
    }

    /// A film, checked: a non-empty timeline, every track with keys in strictly increasing
    /// time, values of its property's kind, and a target that exists in `scene`.
    pub fn new(
        scene: SceneDesc,
        timeline: Timeline,
        tracks: Vec<Track>,
    ) -> Result<Film, AnimError> {
        let Timeline { start, end, rate } = timeline;
        if start >= end || !(rate.is_finite() && rate > 0.0) {
            return Err(AnimError::BadTimeline { start, end, rate });
        }
        for (i, t) in tracks.iter().enumerate() {
            check_track(&scene, i, t)?;
        }
        Ok(Film {
            scene,
            timeline,
            tracks,
        })
    }

    /// The scene as written (every track's property at its written value).
    pub fn base(&self) -> &SceneDesc {
        &self.scene
    }

    pub fn timeline(&self) -> Timeline {
        self.timeline
    }

    pub fn tracks(&self) -> &[Track] {
        &self.tracks
    }

    /// True for a scene without `frames` (one frame, 0..1, no tracks).
    pub fn is_still(&self) -> bool {
        self.timeline == Timeline::STILL && self.tracks.is_empty()
    }

    /// The still scene of `frame`: the scene as written with every track's value at that
    /// frame written in. A pure function of the film and the frame.
    pub fn scene_at(&self, frame: u32) -> Result<SceneDesc, AnimError> {
        let Timeline { start, end, .. } = self.timeline;
        if !(start..end).contains(&frame) {
            return Err(AnimError::FrameOutside { frame, start, end });
        }
        let mut scene = self.scene.clone();
        for (i, track) in self.tracks.iter().enumerate() {
            let value = track_value(track, f64::from(frame)).ok_or(AnimError::BadKeys {
                track: i,
                why: "no keys",
            })?;
            apply(&mut scene, &track.target, value).map_err(|e| match e {
                ApplyError::NoTarget => AnimError::NoTarget { track: i },
                ApplyError::ZeroDirection => AnimError::ZeroDirection { track: i, frame },
            })?;
        }
        Ok(scene)
    }

    /// The DM's work for one frame: [`Film::scene_at`] compiled to a SceneImage.
    pub fn compile_frame(&self, frame: u32, opts: &CompileOptions) -> Result<Compiled, FrameError> {
        let scene = self.scene_at(frame).map_err(FrameError::Anim)?;
        compile(&scene, opts).map_err(|source| FrameError::Dm { frame, source })
    }
}

fn check_track(scene: &SceneDesc, i: usize, t: &Track) -> Result<(), AnimError> {
    let bad = |why| Err(AnimError::BadKeys { track: i, why });
    match (&t.keys, t.target.is_number()) {
        (Keys::Number(_), true) | (Keys::Vector(_), false) => {}
        _ => return bad("the values do not suit the target (a number or a vector)"),
    }
    let times = t.keys.times();
    if times.is_empty() {
        return bad("no keys");
    }
    if times.iter().any(|f| !f.is_finite()) || times.windows(2).any(|w| w[0] >= w[1]) {
        return bad("key times must be finite and strictly increasing");
    }
    let probe = match t.keys {
        Keys::Number(_) => Value::Number(1.0),
        Keys::Vector(_) => Value::Vector([0.0, 1.0, 0.0]),
    };
    apply(&mut scene.clone(), &t.target, probe).map_err(|_| AnimError::NoTarget { track: i })
}

/// A track's value at time `t` (`None` without keys).
pub fn track_value(track: &Track, t: f64) -> Option<Value> {
    let interp = track.interpolation;
    match &track.keys {
        Keys::Number(keys) => {
            let mut v = sample(keys, interp, t)?;
            if interp == Interpolation::Smooth {
                if let Some((a, b)) = segment(keys, t) {
                    v = v.clamp(a.min(b), a.max(b));
                }
            }
            Some(Value::Number(v))
        }
        Keys::Vector(keys) => Some(Value::Vector(match track.target.kind() {
            ValueKind::Rotation => sample_rotation(keys, interp, t)?,
            ValueKind::Bounded if interp == Interpolation::Smooth => {
                let v = sample(keys, interp, t)?;
                match segment(keys, t) {
                    Some((a, b)) => [0, 1, 2].map(|i| v[i].clamp(a[i].min(b[i]), a[i].max(b[i]))),
                    None => v,
                }
            }
            _ => sample(keys, interp, t)?,
        })),
    }
}

/// Euler-angle keys sampled as unit quaternions (slerp, spherical Catmull-Rom). At a key, or
/// outside the keys, or with step interpolation, the key's angles are returned as written.
fn sample_rotation(keys: &[Key<[f64; 3]>], interp: Interpolation, t: f64) -> Option<[f64; 3]> {
    let first = keys.first()?.frame;
    let last = keys.last()?.frame;
    if interp == Interpolation::Step || t <= first || t >= last || keys.iter().any(|k| k.frame == t)
    {
        return sample(keys, Interpolation::Step, t);
    }
    let mut quats: Vec<Key<Quat>> = Vec::with_capacity(keys.len());
    for k in keys {
        let mut q = Quat::from_euler_deg(k.value);
        // Each key on the near side of the previous one: the shorter way round.
        if quats.last().is_some_and(|p| p.value.dot(q) < 0.0) {
            q = -q;
        }
        quats.push(Key {
            frame: k.frame,
            value: q,
        });
    }
    Some(sample(&quats, interp, t)?.to_euler_deg())
}

/// `v / |v|`, or `None` when `v` has no usable direction. The scene loader normalises
/// directions with this same function, so a direction written into a still scene by hand
/// ends up with the same bits as one a track produced.
pub fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        let n = v.map(|x| x / len);
        n.iter().all(|x| x.is_finite()).then_some(n)
    } else {
        None
    }
}

enum ApplyError {
    NoTarget,
    ZeroDirection,
}

fn vector(v: Value) -> Result<[f64; 3], ApplyError> {
    match v {
        Value::Vector(v) => Ok(v),
        Value::Number(_) => Err(ApplyError::NoTarget),
    }
}

fn number(v: Value) -> Result<f64, ApplyError> {
    match v {
        Value::Number(n) => Ok(n),
        Value::Vector(_) => Err(ApplyError::NoTarget),
    }
}

fn rgb(v: Value) -> Result<[f32; 3], ApplyError> {
    Ok(vector(v)?.map(|x| x as f32))
}

fn direction(v: Value) -> Result<[f64; 3], ApplyError> {
    unit(vector(v)?).ok_or(ApplyError::ZeroDirection)
}

/// Writes `value` into the scene at `target`.
fn apply(scene: &mut SceneDesc, target: &Target, value: Value) -> Result<(), ApplyError> {
    match target {
        Target::Camera(p) => {
            let c = &mut scene.camera;
            match p {
                CameraProperty::Eye => c.eye = vector(value)?,
                CameraProperty::LookAt => c.look_at = vector(value)?,
                CameraProperty::Up => c.up = direction(value)?,
                CameraProperty::FovY => c.fov_y_deg = number(value)?,
            }
        }
        Target::Cluster { path, property } => {
            let t = &mut cluster_at(&mut scene.root, path)?.transform;
            match property {
                TransformProperty::Translate => t.translate = vector(value)?,
                TransformProperty::Rotate => t.rotate_deg = vector(value)?,
                TransformProperty::Scale => t.scale = vector(value)?,
            }
        }
        Target::Light { index, property } => {
            let light = scene
                .lights
                .get_mut(*index as usize)
                .ok_or(ApplyError::NoTarget)?;
            apply_light(light, *property, value)?;
        }
        Target::Material { index, property } => {
            let m = scene
                .materials
                .get_mut(*index as usize)
                .ok_or(ApplyError::NoTarget)?;
            apply_material(m, *property, value)?;
        }
        Target::BallCenter { path, ball } => {
            let (last, parent) = path.split_last().ok_or(ApplyError::NoTarget)?;
            let cluster = cluster_at(&mut scene.root, parent)?;
            let Some(Node::Shape(Shape::Blobs { balls, .. })) =
                cluster.children.get_mut(*last as usize)
            else {
                return Err(ApplyError::NoTarget);
            };
            let b = balls.get_mut(*ball as usize).ok_or(ApplyError::NoTarget)?;
            b.center = vector(value)?;
        }
    }
    Ok(())
}

fn apply_light(light: &mut Light, property: LightProperty, value: Value) -> Result<(), ApplyError> {
    match (light, property) {
        (Light::Point { pos, .. } | Light::Spot { pos, .. }, LightProperty::Position) => {
            *pos = vector(value)?;
        }
        (Light::Directional { dir, .. } | Light::Spot { dir, .. }, LightProperty::Direction) => {
            *dir = direction(value)?;
        }
        (
            Light::Directional { color, .. }
            | Light::Point { color, .. }
            | Light::Spot { color, .. },
            LightProperty::Color,
        ) => *color = rgb(value)?,
        _ => return Err(ApplyError::NoTarget),
    }
    Ok(())
}

fn apply_material(
    m: &mut crate::desc::Material,
    property: MaterialProperty,
    value: Value,
) -> Result<(), ApplyError> {
    use MaterialProperty as P;
    match property {
        P::Diffuse => m.diffuse = rgb(value)?,
        P::Transmit => m.transmit = rgb(value)?,
        P::Ambient => m.ambient = Some(rgb(value)?),
        P::Specular => m.specular = number(value)? as f32,
        P::SpecularEdge => m.specular_edge = number(value)? as f32,
        P::Shininess => m.shininess = number(value)? as f32,
        P::Reflect => m.reflect = number(value)? as f32,
        P::ReflectEdge => m.reflect_edge = number(value)? as f32,
        P::Ior => m.ior = number(value)? as f32,
    }
    Ok(())
}

/// The cluster at `path` (child indices from `root`).
fn cluster_at<'a>(root: &'a mut Cluster, path: &[u32]) -> Result<&'a mut Cluster, ApplyError> {
    let mut c = root;
    for &i in path {
        match c.children.get_mut(i as usize) {
            Some(Node::Cluster(sub)) => c = sub,
            _ => return Err(ApplyError::NoTarget),
        }
    }
    Ok(c)
}
