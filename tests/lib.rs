//! Helpers shared by the cross-crate tests in `tests/tests/`.

use links_core::desc::*;
use links_core::dm::{compile, CompileOptions};
use links_core::image::SceneView;
use links_core::num::Real;
use links_core::render::{render_run, Rgb8, Stats, Techniques, Tracer};

/// A material with only the given diffuse colour.
pub fn matte(name: &str, diffuse: [f32; 3]) -> Material {
    Material {
        name: name.into(),
        diffuse,
        specular: 0.0,
        specular_edge: 0.0,
        ..Material::default()
    }
}

/// A scene whose camera sits at the world origin looking down -Z with Y up, so view
/// coordinates are world (x, y, -z).
pub fn scene(width: u32, height: u32, fov_y_deg: f64, shapes: Vec<Shape>) -> SceneDesc {
    let camera = Camera {
        eye: [0.0; 3],
        look_at: [0.0, 0.0, -1.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg,
    };
    let children = shapes.into_iter().map(Node::Shape).collect();
    links_core::testkit::scene::scene_desc(camera, width, height, children)
}

pub fn image_of(desc: &SceneDesc) -> Vec<u8> {
    compile(desc, &CompileOptions::default())
        .expect("scene compiles")
        .bytes
}

/// Render one pixel of a compiled scene.
pub fn pixel<T: Real>(image: &[u8], x: u32, y: u32) -> Rgb8 {
    let view = SceneView::new(image).expect("valid image");
    let mut tracer = Tracer::<T>::new(view);
    let mut out = [[0u8; 3]; 1];
    render_run(&mut tracer, y, x, &mut out).expect("pixel inside frame");
    out[0]
}

/// Render a whole compiled scene, RGB8 rows.
pub fn render_all<T: Real>(image: &[u8]) -> Vec<u8> {
    render_all_with::<T>(image, Techniques::ALL).0
}

/// Render a whole compiled scene with chosen techniques: RGB8 rows and the counts.
pub fn render_all_with<T: Real>(image: &[u8], techniques: Techniques) -> (Vec<u8>, Stats) {
    let view = SceneView::new(image).expect("valid image");
    let f = view.camera::<f32>();
    let mut tracer = Tracer::<T>::with_techniques(view, techniques);
    let mut row = vec![[0u8; 3]; f.width as usize];
    let mut out = Vec::with_capacity((f.width * f.height * 3) as usize);
    for y in 0..f.height {
        render_run(&mut tracer, y, 0, &mut row).expect("row inside frame");
        out.extend(row.iter().flatten());
    }
    (out, tracer.stats)
}

/// A deterministic xorshift generator for property tests.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }
    /// Uniform in [0, 1).
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.f64()
    }
    /// Uniform direction on the unit sphere.
    pub fn unit(&mut self) -> [f64; 3] {
        loop {
            let v = [
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            ];
            let l2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if l2 > 1e-4 && l2 <= 1.0 {
                let l = l2.sqrt();
                return v.map(|c| c / l);
            }
        }
    }
}

/// An icosphere: a closed, convex, consistently wound triangle mesh.
pub fn icosphere(subdivisions: u32, radius: f64, center: [f64; 3]) -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pos: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let norm = |p: [f64; 3]| {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        p.map(|c| c / l)
    };
    for p in &mut pos {
        *p = norm(*p);
    }
    for _ in 0..subdivisions {
        let mut cache = std::collections::HashMap::new();
        let mut mid = |a: u32, b: u32, pos: &mut Vec<[f64; 3]>| -> u32 {
            let key = (a.min(b), a.max(b));
            *cache.entry(key).or_insert_with(|| {
                let (pa, pb) = (pos[a as usize], pos[b as usize]);
                pos.push(norm([0, 1, 2].map(|k| (pa[k] + pb[k]) / 2.0)));
                (pos.len() - 1) as u32
            })
        };
        let mut next = Vec::new();
        for f in &faces {
            let a = mid(f[0], f[1], &mut pos);
            let b = mid(f[1], f[2], &mut pos);
            let c = mid(f[2], f[0], &mut pos);
            next.extend([[f[0], a, c], [f[1], b, a], [f[2], c, b], [a, b, c]]);
        }
        faces = next;
    }
    Mesh {
        source: "icosphere".into(),
        positions: pos
            .iter()
            .map(|p| [0, 1, 2].map(|k| center[k] + radius * p[k]))
            .collect(),
        normals: vec![],
        uvs: vec![],
        faces: faces
            .iter()
            .map(|f| {
                f.map(|i| FaceVertex {
                    position: i,
                    normal: None,
                    uv: None,
                })
            })
            .collect(),
        groups: vec![],
    }
}

/// The image a backend renders: the f32 image itself, or the DM's Q16.16 rewrite of it for
/// fixed point.
pub fn for_backend<T: Real>(img: Vec<u8>) -> Vec<u8> {
    match T::STORAGE {
        links_core::num::Storage::F32 => img,
        links_core::num::Storage::Q16_16 => {
            links_core::fixed_image::to_fixed(&img)
                .expect("scene fits Q16.16")
                .bytes
        }
    }
}

/// The factor an image's lengths carry (2^k of a Q16.16 image; 1 for f32): view-space
/// coordinates of a test scene times this are the coordinates the tracer sees.
pub fn length_scale(img: &[u8]) -> f64 {
    2f64.powi(SceneView::new(img).expect("valid image").scale_exponent() as i32)
}

/// A bundled scene (`scenes/<scene>`) compiled by the DM at `w` x `h` with default options.
pub fn bundled_image(scene: &str, w: u32, h: u32) -> Vec<u8> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(scene);
    links_host::scene_file::compile_at(&path, w, h).unwrap_or_else(|e| panic!("{e}"))
}

/// The host's f32 render of a compiled image on one thread: what every cluster frame must
/// equal bit for bit.
pub fn host_reference(img: &[u8]) -> Vec<u8> {
    links_host::frame::render_frame(img, links_host::frame::Precision::F32, 1, &|| {})
        .expect("renders")
        .rgb
}

/// A frame the root logic writes pixel runs into (`links_core::root::PixelSink`), `w` pixels
/// wide, RGB8.
pub struct FrameSink {
    pub w: usize,
    pub rgb: Vec<u8>,
}

impl FrameSink {
    /// A black `w` x `h` frame.
    pub fn new(w: u32, h: u32) -> Self {
        FrameSink {
            w: w as usize,
            rgb: vec![0; (w * h * 3) as usize],
        }
    }
}

impl links_core::root::PixelSink for FrameSink {
    fn pixels(&mut self, _frame: u16, y: u16, x: u16, rgb: &[u8]) {
        let at = 3 * (y as usize * self.w + x as usize);
        self.rgb[at..at + rgb.len()].copy_from_slice(rgb);
    }
}
