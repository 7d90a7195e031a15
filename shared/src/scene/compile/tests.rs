use super::*;
use crate::desc::*;
use crate::image::SceneView;

/// The scene the DM tests compile: `children` 5 units in front of the eye, 16 x 16 pixels.
fn scene(children: Vec<Node>) -> SceneDesc {
    let camera = Camera {
        eye: [0.0, 0.0, 5.0],
        look_at: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 40.0,
    };
    SceneDesc {
        ambient: [0.1; 3],
        max_depth: 3,
        ..crate::testkit::scene::scene_desc(camera, 16, 16, children)
    }
}

fn quad_mesh(normal: [f64; 3]) -> Mesh {
    let fv = |p, n| FaceVertex {
        position: p,
        normal: Some(n),
        uv: None,
    };
    Mesh {
        source: "quad".into(),
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        normals: vec![normal, [0.3, 0.0, 0.954]],
        uvs: vec![],
        faces: vec![
            [fv(0, 0), fv(1, 0), fv(2, 0)],
            [fv(0, 0), fv(2, 0), fv(3, 1)],
        ],
        groups: vec![],
    }
}

#[test]
fn flat_vertex_normals_are_dropped_and_smooth_ones_kept() {
    let s = scene(vec![Node::Shape(Shape::Mesh {
        mesh: quad_mesh([0.0, 0.0, 1.0]),
        material: 0,
        smooth: false,
    })]);
    let img = compile(&s, &CompileOptions::default()).unwrap().bytes;
    let v = SceneView::new(&img).unwrap();
    assert_eq!(v.count(Section::Triangles), 2);
    assert_eq!(
        v.count(Section::TriNormals),
        1,
        "the face whose corners all carry the face normal needs none"
    );
    // Normals that disagree with the winding are kept: they say which side is outside.
    let s = scene(vec![Node::Shape(Shape::Mesh {
        mesh: quad_mesh([0.0, 0.0, -1.0]),
        material: 0,
        smooth: false,
    })]);
    let img = compile(&s, &CompileOptions::default()).unwrap().bytes;
    assert_eq!(SceneView::new(&img).unwrap().count(Section::TriNormals), 2);
}

#[test]
fn every_shape_is_reachable_exactly_once_in_every_hierarchy() {
    let mut mesh = quad_mesh([0.0, 0.0, 1.0]);
    // Make a bigger mesh: 40 quads in a strip, in two groups.
    let base = mesh.clone();
    for k in 1..40u32 {
        let off = mesh.positions.len() as u32;
        mesh.positions.extend(
            base.positions
                .iter()
                .map(|p| [p[0] + k as f64, p[1], p[2] + 0.1 * k as f64]),
        );
        mesh.faces.extend(base.faces.iter().map(|f| {
            f.map(|v| FaceVertex {
                position: v.position + off,
                ..v
            })
        }));
    }
    mesh.groups = vec![
        MeshGroup {
            name: "a".into(),
            first_face: 0,
        },
        MeshGroup {
            name: "b".into(),
            first_face: 33,
        },
    ];
    let blob = Shape::Blobs {
        balls: vec![Ball {
            center: [0.0; 3],
            radius: 1.0,
            strength: 1.0,
        }],
        threshold: 0.5,
        kernel: BlobKernel::Links,
        material: 0,
    };
    let inner = Cluster {
        name: "inner".into(),
        transform: Transform {
            translate: [1.0, 2.0, 3.0],
            ..Transform::default()
        },
        children: vec![
            Node::Shape(Shape::Box {
                min: [0.0; 3],
                max: [1.0; 3],
                material: 0,
            }),
            Node::Shape(blob),
            Node::Cluster(Cluster::default()),
        ],
    };
    let s = scene(vec![
        Node::Shape(Shape::Mesh {
            mesh,
            material: 0,
            smooth: true,
        }),
        Node::Cluster(inner),
        Node::Shape(Shape::Ellipsoid {
            center: [0.0; 3],
            radii: [1.0; 3],
            rotate_deg: [0.0; 3],
            cut: None,
            material: 0,
        }),
    ]);
    for h in [
        MeshHierarchy::Flat,
        MeshHierarchy::Median,
        MeshHierarchy::Sah,
    ] {
        let img = compile(
            &s,
            &CompileOptions {
                mesh_hierarchy: h,
                ..Default::default()
            },
        )
        .unwrap()
        .bytes;
        let v = SceneView::new(&img).unwrap();
        let mut seen = std::collections::HashMap::new();
        for i in 0..v.node_count() {
            if let Some(l) = v.node::<f64>(i).leaf {
                for k in 0..l.count {
                    let r = l.shape(k);
                    *seen.entry((r.kind as u8, r.index)).or_insert(0) += 1;
                }
            }
            // Subtrees nest: a child's subtree ends no later than its parent's.
            let skip = v.node_skip(i);
            for j in i + 1..skip {
                assert!(
                    v.node_skip(j) <= skip,
                    "{h:?}: node {j} leaves its parent {i}"
                );
            }
        }
        assert_eq!(
            v.node_skip(0),
            v.node_count(),
            "{h:?}: the root spans everything"
        );
        assert_eq!(
            seen.len(),
            80 + 3,
            "{h:?}: 80 triangles, a box, a blob group, an ellipsoid"
        );
        assert!(
            seen.values().all(|&n| n == 1),
            "{h:?}: every shape in exactly one leaf"
        );
    }
}

#[test]
fn mesh_groups_become_sub_clusters() {
    let mut mesh = quad_mesh([0.0, 0.0, 1.0]);
    mesh.groups = vec![
        MeshGroup {
            name: "a".into(),
            first_face: 0,
        },
        MeshGroup {
            name: "b".into(),
            first_face: 1,
        },
    ];
    let s = scene(vec![Node::Shape(Shape::Mesh {
        mesh,
        material: 0,
        smooth: false,
    })]);
    let opts = CompileOptions {
        mesh_hierarchy: MeshHierarchy::Flat,
        ..Default::default()
    };
    let img = compile(&s, &opts).unwrap().bytes;
    let v = SceneView::new(&img).unwrap();
    // Built: root, mesh, group a, its triangle, group b, its triangle. Clusters with one
    // child are dropped (the root holds only the mesh, each group one leaf): the mesh
    // cluster is the root, with one leaf per group.
    let skips: Vec<u32> = (0..v.node_count()).map(|i| v.node_skip(i)).collect();
    let leaves: Vec<bool> = (0..v.node_count()).map(|i| v.node_is_leaf(i)).collect();
    assert_eq!(skips, [3, 2, 3]);
    assert_eq!(leaves, [false, true, true]);
}

#[test]
fn boxes_contain_their_shapes_after_transforms() {
    let t = Transform {
        translate: [1.0, -2.0, 0.5],
        rotate_deg: [30.0, 45.0, 10.0],
        scale: [2.0, 0.5, 1.5],
    };
    let shapes = vec![
        Node::Shape(Shape::Ellipsoid {
            center: [0.5, 0.0, 0.0],
            radii: [1.0, 2.0, 0.5],
            rotate_deg: [10.0, 0.0, 70.0],
            cut: None,
            material: 0,
        }),
        Node::Shape(Shape::Box {
            min: [-1.0, -1.0, -1.0],
            max: [1.0, 0.5, 2.0],
            material: 0,
        }),
        Node::Shape(Shape::Triangle {
            v: [[0.0, 0.0, 0.0], [3.0, 0.0, 1.0], [0.0, 2.0, -1.0]],
            normals: None,
            uv: None,
            material: 0,
        }),
    ];
    let s = scene(vec![Node::Cluster(Cluster {
        name: "c".into(),
        transform: t,
        children: shapes,
    })]);
    let img = compile(&s, &CompileOptions::default()).unwrap().bytes;
    let v = SceneView::new(&img).unwrap();
    // Sample each shape's surface densely (through its own local frame) and check the leaf
    // box and every enclosing cluster box contain the samples.
    let contains_all = |pts: &[crate::geom::Vec3<f64>], leaf: u32| {
        for i in 0..v.node_count() {
            let n = v.node::<f64>(i);
            if i <= leaf && n.skip > leaf {
                for p in pts {
                    assert!(
                        n.bounds.contains(*p),
                        "node {i} box {:?} misses {p:?}",
                        n.bounds
                    );
                }
            }
        }
    };
    for leaf in 0..v.node_count() {
        let Some(l) = v.node::<f64>(leaf).leaf else {
            continue;
        };
        let r = l.shape(0);
        let mut pts = Vec::new();
        for a in 0..24 {
            for b in 0..12 {
                let (th, ph) = (a as f64 * 0.2618, b as f64 * 0.2618 + 0.1);
                let q = crate::geom::Vec3::new(ph.sin() * th.cos(), ph.cos(), ph.sin() * th.sin());
                match r.kind {
                    ShapeKind::Ellipsoid => {
                        let e = v.ellipsoid::<f64>(r.index).shape;
                        pts.push(e.center + e.l.mul_vec(q));
                    }
                    ShapeKind::Box => {
                        let bx = v.boxshape::<f64>(r.index).shape;
                        let c = q * (1.0 / q.abs().max_component());
                        pts.push(bx.center + bx.l.mul_vec(c));
                    }
                    _ => {}
                }
            }
        }
        if r.kind == ShapeKind::Triangle {
            pts.extend(v.triangle::<f64>(r.index).tri.p);
        }
        assert!(!pts.is_empty());
        contains_all(&pts, leaf);
    }
}

#[test]
fn texture_sizes_whose_byte_count_overflows_are_rejected() {
    let quad = || {
        Node::Shape(Shape::Mesh {
            mesh: quad_mesh([0.0, 0.0, 1.0]),
            material: 0,
            smooth: false,
        })
    };
    // 65536 x 65536 x 3 wraps a u32 to 0 bytes: no texels "needed".
    for (width, height) in [(65_536, 65_536), (u32::MAX, 2), (3, 4)] {
        let mut s = scene(vec![quad()]);
        s.textures = vec![Texture {
            name: "t".into(),
            width,
            height,
            rgb: vec![],
        }];
        assert_eq!(
            compile(&s, &CompileOptions::default()).err(),
            Some(DmError::BadIndex {
                what: "texture 0 ('t') has a bad size".into()
            }),
            "{width} x {height}"
        );
    }
}

#[test]
fn degenerate_inputs_are_rejected() {
    let zero_scale = Transform {
        scale: [1.0, 0.0, 1.0],
        ..Transform::default()
    };
    let s = scene(vec![Node::Cluster(Cluster {
        name: "flat".into(),
        transform: zero_scale,
        children: vec![],
    })]);
    assert!(matches!(
        compile(&s, &CompileOptions::default()),
        Err(DmError::DegenerateTransform { .. })
    ));
    let stretch = Transform {
        scale: [1.0, 2.0, 1.0],
        ..Transform::default()
    };
    let blobs = Shape::Blobs {
        balls: vec![Ball {
            center: [0.0; 3],
            radius: 1.0,
            strength: 1.0,
        }],
        threshold: 0.5,
        kernel: BlobKernel::Links,
        material: 0,
    };
    let s = scene(vec![Node::Cluster(Cluster {
        name: "s".into(),
        transform: stretch,
        children: vec![Node::Shape(blobs)],
    })]);
    let e = compile(&s, &CompileOptions::default()).unwrap_err();
    assert_eq!(
        e,
        DmError::NonUniformBlobScale {
            cluster: "root/s".into()
        }
    );
    let mut s = scene(vec![]);
    s.camera.up = [0.0, 0.0, 1.0];
    assert!(matches!(
        compile(&s, &CompileOptions::default()),
        Err(DmError::DegenerateCamera(_))
    ));
    let s = scene(vec![]);
    let opts = CompileOptions {
        max_depth: Some(99),
        ..Default::default()
    };
    assert!(matches!(compile(&s, &opts), Err(DmError::BadSetting(_))));
}

/// Every number of a scene file fits f32, but a transform can carry one beyond it: the
/// image would hold infinities (and f32 and f64 renders of it differ).
#[test]
fn values_beyond_f32_after_the_transforms_are_rejected() {
    let sphere = |center| {
        Node::Shape(Shape::Ellipsoid {
            center,
            radii: [1.0; 3],
            rotate_deg: [0.0; 3],
            cut: None,
            material: 0,
        })
    };
    // 3e38 is an f32; scaled by 10 it is not.
    let s = scene(vec![Node::Cluster(Cluster {
        name: "far".into(),
        transform: Transform {
            scale: [10.0; 3],
            ..Transform::default()
        },
        children: vec![sphere([0.0, 0.0, -3e38])],
    })]);
    assert_eq!(
        compile(&s, &CompileOptions::default()).unwrap_err(),
        DmError::BeyondF32 {
            section: Section::Ellipsoids.name(),
            record: 0
        }
    );
    // A point light 3e38 behind an eye at 3e38 is 6e38 away in view coordinates.
    let mut s = scene(vec![sphere([0.0; 3])]);
    s.camera.eye = [0.0, 0.0, 3e38];
    s.lights = vec![Light::Point {
        pos: [0.0, 0.0, -3e38],
        color: [1.0; 3],
        falloff: false,
    }];
    let e = compile(&s, &CompileOptions::default()).unwrap_err();
    assert_eq!(
        e,
        DmError::BeyondF32 {
            section: "lights",
            record: 0
        }
    );
    assert_eq!(
        e.to_string(),
        "lights record 0 holds a value beyond the f32 range (about ±3.4e38) after the \
         cluster and view transforms"
    );
    // The same scene nearer the origin compiles.
    s.camera.eye = [0.0, 0.0, 3e37];
    s.lights = vec![Light::Point {
        pos: [0.0, 0.0, -3e37],
        color: [1.0; 3],
        falloff: false,
    }];
    compile(&s, &CompileOptions::default()).unwrap();
}

/// Materials with their own ambient colour keep their indices and point at ambient records
/// written after every material: 64 bytes per such material, none for the others, and the
/// view decodes each material's ambient (or none) back.
#[test]
fn ambient_colours_add_one_record_each_after_the_materials() {
    let sphere = |material| {
        Node::Shape(Shape::Ellipsoid {
            center: [0.0; 3],
            radii: [1.0; 3],
            rotate_deg: [0.0; 3],
            cut: None,
            material,
        })
    };
    let mut desc = scene(vec![sphere(0), sphere(1), sphere(2)]);
    let m = |d: f32| Material {
        diffuse: [d; 3],
        ..Material::default()
    };
    desc.materials = vec![m(0.1), m(0.2), m(0.3)];
    let plain = compile(&desc, &CompileOptions::default()).unwrap().bytes;
    desc.materials[0].ambient = Some([0.25, 0.5, 0.75]);
    desc.materials[2].ambient = Some([1.0, 0.0, 0.5]);
    let with = compile(&desc, &CompileOptions::default()).unwrap().bytes;
    assert_eq!(with.len(), plain.len() + 2 * material::SIZE);
    let v = SceneView::new(&with).unwrap();
    assert_eq!(v.count(Section::Materials), 5);
    let amb = |i| v.material::<f32>(i).ambient.map(|a| [a.x, a.y, a.z]);
    assert_eq!(amb(0), Some([0.25, 0.5, 0.75]));
    assert_eq!(amb(1), None);
    assert_eq!(amb(2), Some([1.0, 0.0, 0.5]));
    assert_eq!(v.material::<f32>(2).diffuse.x, 0.3);
    // The same scene without ambient colours is the image it always was: no flags set.
    let p = SceneView::new(&plain).unwrap();
    for i in 0..3 {
        assert!(p.material::<f32>(i).ambient.is_none());
    }
    // The Q16.16 rewrite converts the ambient records' colours.
    let fixed = crate::fixed_image::to_fixed(&with).unwrap().bytes;
    let f = SceneView::new(&fixed).unwrap();
    let a = f.material::<crate::num::Fx>(0).ambient.unwrap();
    use crate::num::Real;
    assert_eq!(
        [a.x.to_f32(), a.y.to_f32(), a.z.to_f32()],
        [0.25, 0.5, 0.75]
    );
}

/// An ambient index past the Materials section, or one without the flag, or an unknown flag
/// bit, is a bad reference.
#[test]
fn bad_ambient_references_are_rejected() {
    let mut desc = scene(vec![Node::Shape(Shape::Ellipsoid {
        center: [0.0; 3],
        radii: [1.0; 3],
        rotate_deg: [0.0; 3],
        cut: None,
        material: 0,
    })]);
    desc.materials[0].ambient = Some([0.5; 3]);
    let img = compile(&desc, &CompileOptions::default()).unwrap().bytes;
    let v = SceneView::new(&img).unwrap();
    let at = v.record_range(Section::Materials, 0).unwrap().start;
    assert_eq!(img[at + material::FLAGS], material::OWN_AMBIENT);
    assert_eq!(img[at + material::AMBIENT], 1);
    for (field, value) in [
        (material::AMBIENT, 2u8),
        (material::FLAGS, 0),
        (material::FLAGS, 3),
        (material::TARGET, 4),
    ] {
        let mut bad = img.clone();
        bad[at + field] = value;
        assert!(
            matches!(
                SceneView::new(&bad),
                Err(crate::image::ImageError::BadReference {
                    section: 1,
                    record: 0
                })
            ),
            "field {field} = {value} accepted"
        );
    }
}
