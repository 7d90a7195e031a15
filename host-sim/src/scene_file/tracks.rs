//! Time in the scene file: `frames: (start, end, rate)` and `tracks: [...]` as written, and
//! their resolution against the loaded scene into [`links_core::anim`]'s film model.
//!
//! A track's target, each key's time and each key's value are [`Located`], so a problem found
//! only once the whole file is known (an unknown cluster, a key outside the frames, a value
//! wrong for its target) is reported at its line and column by replaying the parse.

use std::collections::HashMap;

use links_core::anim::{
    CameraProperty, Interpolation, Key, Keys, LightProperty, MaterialProperty, Target, Timeline,
    Track, TransformProperty,
};
use links_core::desc;
use serde::Deserialize;

use super::error::SceneError;
use super::format::Located;
use super::values as v;
use super::values::{check_number, Check, KeyTime, KeyValue, Num, NumVec};

fn default_rate() -> f64 {
    24.0
}

#[derive(Debug, Deserialize)]
#[serde(rename = "Frames", deny_unknown_fields)]
struct RawFrames {
    #[serde(default, deserialize_with = "v::frame_start")]
    start: u32,
    #[serde(deserialize_with = "v::frame_end")]
    end: u32,
    #[serde(default = "default_rate", deserialize_with = "v::rate")]
    rate: f64,
}

/// `frames: (start: 0, end: 48, rate: 24)`: frames `start..end` (end excluded).
#[derive(Debug, Deserialize)]
#[serde(try_from = "RawFrames")]
pub(super) struct FramesFile(pub Timeline);

impl TryFrom<RawFrames> for FramesFile {
    type Error = String;

    fn try_from(f: RawFrames) -> Result<Self, String> {
        if f.start >= f.end {
            return Err(format!(
                "the film has no frames: start ({}) must be less than end ({}), which is one \
                 past the last frame",
                f.start, f.end
            ));
        }
        Ok(FramesFile(Timeline {
            start: f.start,
            end: f.end,
            rate: f.rate,
        }))
    }
}

#[derive(Clone, Copy, Debug, Deserialize)]
pub(super) enum CameraPropFile {
    Eye,
    LookAt,
    Up,
    FovY,
}

#[derive(Clone, Copy, Debug, Deserialize)]
pub(super) enum TransformPropFile {
    Translate,
    Rotate,
    Scale,
}

#[derive(Clone, Copy, Debug, Deserialize)]
pub(super) enum LightPropFile {
    Position,
    Direction,
    Color,
}

#[derive(Clone, Copy, Debug, Deserialize)]
pub(super) enum MaterialPropFile {
    Diffuse,
    Specular,
    SpecularEdge,
    Shininess,
    Reflect,
    ReflectEdge,
    Transmit,
    Ior,
    Ambient,
}

#[derive(Clone, Copy, Debug, Deserialize)]
pub(super) enum BallPropFile {
    Center,
}

/// What a track drives, as written: `Camera(Eye)`, `Cluster("arm", Rotate)`,
/// `Light(0, Color)`, `Material("red", Diffuse)`, `Ball("wax", 2, Center)`.
#[derive(Debug, Deserialize)]
#[serde(rename = "Target")]
pub(super) enum TargetFile {
    Camera(CameraPropFile),
    Cluster(String, TransformPropFile),
    Light(u32, LightPropFile),
    Material(String, MaterialPropFile),
    Ball(String, u32, BallPropFile),
}

#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(rename = "Interpolation")]
pub(super) enum InterpolationFile {
    Step,
    #[default]
    Linear,
    Smooth,
}

impl From<InterpolationFile> for Interpolation {
    fn from(i: InterpolationFile) -> Self {
        match i {
            InterpolationFile::Step => Interpolation::Step,
            InterpolationFile::Linear => Interpolation::Linear,
            InterpolationFile::Smooth => Interpolation::Smooth,
        }
    }
}

/// `(time, value)`.
#[derive(Debug, Deserialize)]
#[serde(rename = "Key")]
pub(super) struct KeyFile(pub Located<KeyTime>, pub Located<KeyValue>);

#[derive(Debug, Deserialize)]
#[serde(rename = "Track", deny_unknown_fields)]
struct RawTrack {
    target: Located<TargetFile>,
    #[serde(default)]
    interpolation: InterpolationFile,
    keys: Vec<KeyFile>,
}

/// `Track(target: ..., interpolation: ..., keys: [(time, value), ...])`, at least one key.
#[derive(Debug, Deserialize)]
#[serde(try_from = "RawTrack")]
pub(super) struct TrackFile {
    pub target: Located<TargetFile>,
    pub interpolation: InterpolationFile,
    pub keys: Vec<KeyFile>,
}

impl TryFrom<RawTrack> for TrackFile {
    type Error = String;

    fn try_from(t: RawTrack) -> Result<Self, String> {
        if t.keys.is_empty() {
            return Err("a track needs at least one key `(time, value)`".into());
        }
        Ok(TrackFile {
            target: t.target,
            interpolation: t.interpolation,
            keys: t.keys,
        })
    }
}

// ---- resolution --------------------------------------------------------------------------------

/// What tracks may name, gathered while the cluster tree is resolved: clusters and named
/// Blobs by name (a name may occur several times; a track needs it once) with their paths
/// of child indices from the root, and each Blobs' ball count.
#[derive(Default)]
pub(super) struct Names {
    pub clusters: HashMap<String, Vec<Vec<u32>>>,
    pub blobs: HashMap<String, Vec<(Vec<u32>, usize)>>,
}

/// Everything track resolution reads.
pub(super) struct TrackScope<'a> {
    pub timeline: Option<Timeline>,
    pub names: &'a Names,
    pub materials: &'a [desc::Material],
    pub lights: &'a [desc::Light],
    /// A positioned error at the [`Located`] or [`super::format::Ref`] numbered `id`.
    pub at: &'a dyn Fn(u32, String) -> SceneError,
}

/// How a property's key values are checked.
struct ValueRule {
    what: &'static str,
    number: bool,
    /// A single number stands for the same value on every axis.
    splat: bool,
    check: Check,
    /// Non-zero as a whole (directions).
    direction: bool,
}

const fn rule(what: &'static str, number: bool, splat: bool, check: Check) -> ValueRule {
    ValueRule {
        what,
        number,
        splat,
        check,
        direction: false,
    }
}

const DIRECTION: ValueRule = ValueRule {
    what: "direction component",
    number: false,
    splat: false,
    check: Check::Finite,
    direction: true,
};

fn value_rule(target: &Target) -> ValueRule {
    use MaterialProperty as M;
    match target {
        Target::Camera(CameraProperty::Eye | CameraProperty::LookAt)
        | Target::BallCenter { .. } => rule("coordinate", false, false, Check::Finite),
        Target::Camera(CameraProperty::Up) => DIRECTION,
        Target::Camera(CameraProperty::FovY) => {
            rule("field of view", true, false, Check::Between(0.0, 180.0))
        }
        Target::Cluster { property, .. } => match property {
            TransformProperty::Translate => rule("coordinate", false, false, Check::Finite),
            TransformProperty::Rotate => rule("angle", false, false, Check::Finite),
            TransformProperty::Scale => rule("scale factor", false, true, Check::Positive),
        },
        Target::Light { property, .. } => match property {
            LightProperty::Position => rule("coordinate", false, false, Check::Finite),
            LightProperty::Direction => DIRECTION,
            LightProperty::Color => rule("colour channel", false, true, Check::NonNegative),
        },
        Target::Material { property, .. } => match property {
            M::Diffuse | M::Transmit | M::Ambient => {
                rule("colour channel", false, true, Check::Unit)
            }
            M::Specular | M::SpecularEdge | M::Reflect | M::ReflectEdge => {
                rule("coefficient", true, false, Check::Unit)
            }
            M::Shininess => rule("shininess", true, false, Check::NonNegative),
            M::Ior => rule("index of refraction", true, false, Check::AtLeast(1.0)),
        },
    }
}

impl TrackScope<'_> {
    /// The film's tracks, each target found and every key checked.
    pub(super) fn resolve(&self, tracks: Vec<TrackFile>) -> Result<Vec<Track>, SceneError> {
        let mut out = Vec::with_capacity(tracks.len());
        for t in tracks {
            let Some(timeline) = self.timeline else {
                return Err((self.at)(
                    t.target.id,
                    "tracks need the film's frames: add `frames: (start: 0, end: N)` to the \
                     scene"
                        .into(),
                ));
            };
            let target = self.target(&t.target)?;
            let keys = self.keys(&target, &t.keys, timeline)?;
            out.push(Track {
                target,
                interpolation: t.interpolation.into(),
                keys,
            });
        }
        Ok(out)
    }

    fn target(&self, t: &Located<TargetFile>) -> Result<Target, SceneError> {
        let fail = |message: String| Err((self.at)(t.id, message));
        Ok(match &t.value {
            TargetFile::Camera(p) => Target::Camera(match p {
                CameraPropFile::Eye => CameraProperty::Eye,
                CameraPropFile::LookAt => CameraProperty::LookAt,
                CameraPropFile::Up => CameraProperty::Up,
                CameraPropFile::FovY => CameraProperty::FovY,
            }),
            TargetFile::Cluster(name, p) => Target::Cluster {
                path: match self.unique(&self.names.clusters, name, "cluster") {
                    Ok(path) => path.clone(),
                    Err(m) => return fail(m),
                },
                property: match p {
                    TransformPropFile::Translate => TransformProperty::Translate,
                    TransformPropFile::Rotate => TransformProperty::Rotate,
                    TransformPropFile::Scale => TransformProperty::Scale,
                },
            },
            TargetFile::Light(index, p) => match self.light(*index, *p) {
                Ok(target) => target,
                Err(m) => return fail(m),
            },
            TargetFile::Material(name, p) => match self.material(name, *p) {
                Ok(target) => target,
                Err(m) => return fail(m),
            },
            TargetFile::Ball(name, ball, BallPropFile::Center) => {
                let (path, balls) = match self.unique(&self.names.blobs, name, "Blobs shape") {
                    Ok(found) => found,
                    Err(m) => return fail(m),
                };
                if *ball as usize >= *balls {
                    return fail(format!(
                        "the Blobs shape \"{name}\" has {balls} balls (0 to {}); there is no ball {ball}",
                        balls - 1
                    ));
                }
                Target::BallCenter {
                    path: path.clone(),
                    ball: *ball,
                }
            }
        })
    }

    /// The one entry named `name`, or why not.
    fn unique<'n, T>(
        &self,
        map: &'n HashMap<String, Vec<T>>,
        name: &str,
        kind: &str,
    ) -> Result<&'n T, String> {
        match map.get(name).map(Vec::as_slice) {
            Some([one]) => Ok(one),
            Some(many) => Err(format!(
                "{} {kind}s are named \"{name}\": a track needs a name used once",
                many.len()
            )),
            None => {
                let mut known: Vec<&str> = map.keys().map(String::as_str).collect();
                known.sort_unstable();
                let shown: Vec<String> =
                    known.iter().take(12).map(|n| format!("\"{n}\"")).collect();
                Err(if shown.is_empty() {
                    format!("unknown {kind} \"{name}\"; the scene names no {kind}s")
                } else {
                    format!(
                        "unknown {kind} \"{name}\"; the scene names {kind}s {}",
                        shown.join(", ")
                    )
                })
            }
        }
    }

    fn light(&self, index: u32, p: LightPropFile) -> Result<Target, String> {
        let n = self.lights.len();
        let Some(light) = self.lights.get(index as usize) else {
            return Err(if n == 0 {
                format!("there is no light {index}: the scene has no lights")
            } else {
                format!(
                    "there is no light {index}: the scene has {n} lights (0 to {})",
                    n - 1
                )
            });
        };
        let (kind, has_pos, has_dir) = match light {
            desc::Light::Directional { .. } => ("Directional", false, true),
            desc::Light::Point { .. } => ("Point", true, false),
            desc::Light::Spot { .. } => ("Spot", true, true),
        };
        let property = match p {
            LightPropFile::Position if !has_pos => {
                return Err(format!("light {index} is {kind}: it has no position"))
            }
            LightPropFile::Direction if !has_dir => {
                return Err(format!("light {index} is {kind}: it has no direction"))
            }
            LightPropFile::Position => LightProperty::Position,
            LightPropFile::Direction => LightProperty::Direction,
            LightPropFile::Color => LightProperty::Color,
        };
        Ok(Target::Light { index, property })
    }

    fn material(&self, name: &str, p: MaterialPropFile) -> Result<Target, String> {
        let Some(index) = self.materials.iter().position(|m| m.name == name) else {
            let names: Vec<String> = self
                .materials
                .iter()
                .take(12)
                .map(|m| format!("\"{}\"", m.name))
                .collect();
            return Err(format!(
                "unknown material \"{name}\"; the scene defines materials {}",
                names.join(", ")
            ));
        };
        use MaterialPropFile as F;
        use MaterialProperty as P;
        let property = match p {
            F::Diffuse => P::Diffuse,
            F::Specular => P::Specular,
            F::SpecularEdge => P::SpecularEdge,
            F::Shininess => P::Shininess,
            F::Reflect => P::Reflect,
            F::ReflectEdge => P::ReflectEdge,
            F::Transmit => P::Transmit,
            F::Ior => P::Ior,
            F::Ambient => P::Ambient,
        };
        Ok(Target::Material {
            index: index as u32,
            property,
        })
    }

    /// The keys, in increasing time within the frames, each value valid for `target`.
    fn keys(&self, target: &Target, keys: &[KeyFile], tl: Timeline) -> Result<Keys, SceneError> {
        let rule = value_rule(target);
        let mut numbers = Vec::new();
        let mut vectors = Vec::new();
        let mut previous: Option<f64> = None;
        for KeyFile(time, value) in keys {
            let t = time.value.0;
            if !(f64::from(tl.start)..=f64::from(tl.end)).contains(&t) {
                return Err((self.at)(
                    time.id,
                    format!(
                        "a key at frame {} is outside the film's frames {}..{} (keys may lie \
                         from {} to {})",
                        Num(t),
                        tl.start,
                        tl.end,
                        tl.start,
                        tl.end
                    ),
                ));
            }
            if let Some(p) = previous.filter(|&p| t <= p) {
                return Err((self.at)(
                    time.id,
                    format!(
                        "keys out of order: a key at frame {} follows one at frame {}; write \
                         keys in increasing time, each time once",
                        Num(t),
                        Num(p)
                    ),
                ));
            }
            previous = Some(t);
            let checked = check_value(&rule, value.value).map_err(|m| (self.at)(value.id, m))?;
            match checked {
                KeyValue::Number(n) => numbers.push(Key { frame: t, value: n }),
                KeyValue::Vector(v) => vectors.push(Key { frame: t, value: v }),
            }
        }
        Ok(if rule.number {
            Keys::Number(numbers)
        } else {
            Keys::Vector(vectors)
        })
    }
}

/// A key value checked against its property's rule (a number splat to a vector where the
/// property allows it).
fn check_value(rule: &ValueRule, value: KeyValue) -> Result<KeyValue, String> {
    match (value, rule.number) {
        (KeyValue::Number(n), true) => check_number(n, rule.what, rule.check).map(KeyValue::Number),
        (KeyValue::Vector(v), true) => Err(format!(
            "expected a single number ({}) for this target, found {}",
            rule.what,
            NumVec(&v)
        )),
        (KeyValue::Number(n), false) if rule.splat => {
            check_number(n, rule.what, rule.check).map(|n| KeyValue::Vector([n; 3]))
        }
        (KeyValue::Number(n), false) => Err(format!(
            "expected a vector (x, y, z) of {}s for this target, found the single number {}",
            rule.what,
            Num(n)
        )),
        (KeyValue::Vector(v), false) => {
            for x in v {
                check_number(x, rule.what, rule.check)?;
            }
            if rule.direction && v::normalize(v).is_none() {
                return Err(format!(
                    "expected a direction (a non-zero vector), found {}",
                    NumVec(&v)
                ));
            }
            Ok(KeyValue::Vector(v))
        }
    }
}

/// The tracks that follow from the format's defaults: a material that leaves out
/// `specular_edge` (`reflect_edge`) has the edge equal to `specular` (`reflect`), so a track
/// on the one drives the other too, unless the edge has a track of its own.
pub(super) fn edge_tracks(tracks: &mut Vec<Track>, edge_follows: &[(bool, bool)]) {
    use MaterialProperty as P;
    let mut extra = Vec::new();
    for t in tracks.iter() {
        let Target::Material { index, property } = t.target else {
            continue;
        };
        let (spec_follows, refl_follows) = edge_follows
            .get(index as usize)
            .copied()
            .unwrap_or_default();
        let edge = match property {
            P::Specular if spec_follows => P::SpecularEdge,
            P::Reflect if refl_follows => P::ReflectEdge,
            _ => continue,
        };
        let own = Target::Material {
            index,
            property: edge,
        };
        if !tracks.iter().any(|o| o.target == own) {
            extra.push(Track {
                target: own,
                ..t.clone()
            });
        }
    }
    tracks.extend(extra);
}
