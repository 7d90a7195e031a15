//! A small Wavefront OBJ reader: `v`, `vn`, `vt`, `f` (all four vertex forms, negative
//! indices, polygons fan-triangulated), and `g`/`o` groups (the model's parts, which become
//! sub-clusters). Smoothing and material statements are ignored.

use links_core::desc::{FaceVertex, Mesh, MeshGroup};

use super::error::SceneError;
use super::values::{degenerate_triangle, f32_range_error, normalize};

/// Statements that are accepted and ignored: smoothing groups, materials (the scene
/// file assigns the material), and point/line/curve-parameter elements (nothing to render).
const IGNORED: &[&str] = &[
    "s",
    "usemtl",
    "mtllib",
    "l",
    "p",
    "vp",
    "mg",
    "lod",
    "shadow_obj",
    "trace_obj",
];

/// Parses OBJ `text`; `file` names it in errors, `source` becomes [`Mesh::source`].
pub(crate) fn parse_obj(text: &str, file: &str, source: &str) -> Result<Mesh, SceneError> {
    let mut mesh = Mesh {
        source: source.to_string(),
        positions: Vec::new(),
        normals: Vec::new(),
        uvs: Vec::new(),
        faces: Vec::new(),
        groups: Vec::new(),
    };
    for (line_idx, raw_line) in text.lines().enumerate() {
        let line_no = line_idx + 1;
        let line = raw_line.split('#').next().unwrap_or("");
        let mut tokens = Tokens::new(line);
        let Some((kw_col, keyword)) = tokens.next() else {
            continue;
        };
        let err = |col: Option<usize>, message: String| SceneError::Obj {
            file: file.to_string(),
            line: Some(line_no),
            col,
            message,
        };
        match keyword {
            "g" | "o" => {
                let name = tokens.map(|(_, t)| t).collect::<Vec<_>>().join(" ");
                let first_face = mesh.faces.len() as u32;
                // A group with no faces yet is renamed, not kept empty.
                if mesh
                    .groups
                    .last()
                    .is_some_and(|g| g.first_face == first_face)
                {
                    mesh.groups.pop();
                }
                mesh.groups.push(MeshGroup { name, first_face });
            }
            "v" => {
                let nums =
                    numbers(&mut tokens, 3, 7, "v x y z [w]").map_err(|(c, m)| err(Some(c), m))?;
                mesh.positions.push([nums[0], nums[1], nums[2]]);
            }
            "vn" => {
                let nums =
                    numbers(&mut tokens, 3, 3, "vn x y z").map_err(|(c, m)| err(Some(c), m))?;
                let n = [nums[0], nums[1], nums[2]];
                let n = normalize(n).ok_or_else(|| {
                    err(
                        Some(kw_col),
                        "a normal must be a non-zero vector, found (0, 0, 0)".to_string(),
                    )
                })?;
                mesh.normals.push(n);
            }
            "vt" => {
                let nums =
                    numbers(&mut tokens, 1, 3, "vt u [v [w]]").map_err(|(c, m)| err(Some(c), m))?;
                mesh.uvs
                    .push([nums[0], nums.get(1).copied().unwrap_or(0.0)]);
            }
            "f" => add_face(&mut mesh, &mut tokens, kw_col).map_err(|(c, m)| err(c, m))?,
            kw if IGNORED.contains(&kw) => {}
            kw => {
                return Err(err(
                    Some(kw_col),
                    format!(
                        "unsupported OBJ statement `{kw}` (supported: v, vn, vt, f; ignored: {})",
                        IGNORED.join(", ")
                    ),
                ))
            }
        }
    }
    if mesh.faces.is_empty() {
        return Err(SceneError::Obj {
            file: file.to_string(),
            line: None,
            col: None,
            message: "the file has no faces (`f` lines)".to_string(),
        });
    }
    if mesh.positions.len() > u32::MAX as usize
        || mesh.normals.len() > u32::MAX as usize
        || mesh.uvs.len() > u32::MAX as usize
    {
        return Err(SceneError::Obj {
            file: file.to_string(),
            line: None,
            col: None,
            message: "too many vertices (the limit is 2^32 - 1)".to_string(),
        });
    }
    Ok(mesh)
}

/// An `f` statement: the polygon fan-triangulated into `mesh.faces`, dropping zero-area
/// triangles. An error is `(column, message)`.
fn add_face(
    mesh: &mut Mesh,
    tokens: &mut Tokens<'_>,
    kw_col: usize,
) -> Result<(), (Option<usize>, String)> {
    let mut verts = Vec::new();
    for (col, tok) in tokens.by_ref() {
        verts.push(face_vertex(tok, mesh).map_err(|m| (Some(col), m))?);
    }
    if verts.len() < 3 {
        return Err((
            Some(kw_col),
            format!("a face needs at least 3 vertices, found {}", verts.len()),
        ));
    }
    let pos = |fv: &FaceVertex| mesh.positions[fv.position as usize];
    let mut added = 0;
    for i in 1..verts.len() - 1 {
        let tri = [verts[0], verts[i], verts[i + 1]];
        if degenerate_triangle(&[pos(&tri[0]), pos(&tri[1]), pos(&tri[2])]) {
            continue;
        }
        mesh.faces.push(tri);
        added += 1;
    }
    if added == 0 {
        return Err((
            Some(kw_col),
            if verts.len() == 3 {
                "degenerate triangle: its vertices have zero area \
                 (they coincide or lie on one line)"
                    .to_string()
            } else {
                format!(
                    "degenerate polygon: all {} vertices lie on one line \
                     (zero area)",
                    verts.len()
                )
            },
        ));
    }
    Ok(())
}

/// Whitespace-separated tokens with their 1-based character column.
struct Tokens<'a> {
    line: &'a str,
    chars: std::iter::Peekable<std::iter::Enumerate<std::str::CharIndices<'a>>>,
}

impl<'a> Tokens<'a> {
    fn new(line: &'a str) -> Self {
        Self {
            line,
            chars: line.char_indices().enumerate().peekable(),
        }
    }
}

impl<'a> Iterator for Tokens<'a> {
    type Item = (usize, &'a str);

    fn next(&mut self) -> Option<(usize, &'a str)> {
        while self
            .chars
            .peek()
            .is_some_and(|(_, (_, c))| c.is_whitespace())
        {
            self.chars.next();
        }
        let (col, (start, _)) = self.chars.next()?;
        let mut end = self.line.len();
        while let Some(&(_, (i, c))) = self.chars.peek() {
            if c.is_whitespace() {
                end = i;
                break;
            }
            self.chars.next();
        }
        Some((col + 1, &self.line[start..end]))
    }
}

/// Reads `min..=max` finite numbers within the f32 range (the format the mesh compiles to, see
/// [`f32_range_error`]); errors carry a column.
fn numbers(
    tokens: &mut Tokens<'_>,
    min: usize,
    max: usize,
    form: &str,
) -> Result<Vec<f64>, (usize, String)> {
    let mut out = Vec::new();
    let mut last_col = 1;
    for (col, tok) in tokens {
        last_col = col;
        if out.len() == max {
            return Err((col, format!("too many numbers: expected `{form}`")));
        }
        let v: f64 = tok
            .parse()
            .map_err(|_| (col, format!("expected a number, found `{tok}`")))?;
        if !v.is_finite() {
            return Err((col, format!("expected a finite number, found `{tok}`")));
        }
        if let Some(e) = f32_range_error(v, "a number", &format_args!("`{tok}`")) {
            return Err((col, e));
        }
        out.push(v);
    }
    if out.len() < min {
        return Err((
            last_col,
            format!("too few numbers: expected `{form}`, found {}", out.len()),
        ));
    }
    Ok(out)
}

/// Parses `a`, `a/b`, `a//c` or `a/b/c` into indices checked against what is defined so far.
fn face_vertex(tok: &str, mesh: &Mesh) -> Result<FaceVertex, String> {
    let mut parts = tok.split('/');
    let p = parts.next().unwrap_or("");
    let t = parts.next();
    let n = parts.next();
    if parts.next().is_some() {
        return Err(format!(
            "bad face vertex `{tok}`: expected v, v/vt, v//vn or v/vt/vn"
        ));
    }
    let position = index(p, mesh.positions.len(), ("vertex", "vertices"), tok)?;
    let uv = match t {
        None | Some("") => None,
        Some(t) => Some(index(
            t,
            mesh.uvs.len(),
            ("texture coordinate", "texture coordinates"),
            tok,
        )?),
    };
    let normal = match n {
        None => None,
        Some(n) => Some(index(n, mesh.normals.len(), ("normal", "normals"), tok)?),
    };
    Ok(FaceVertex {
        position,
        normal,
        uv,
    })
}

/// A 1-based (or negative, relative) OBJ index into an array of `count` items -> 0-based.
/// `what` names the element in singular and plural.
fn index(s: &str, count: usize, what: (&str, &str), tok: &str) -> Result<u32, String> {
    let (one, many) = what;
    let i: i64 = s.parse().map_err(|_| {
        format!("bad face vertex `{tok}`: expected an integer {one} index, found `{s}`")
    })?;
    let resolved = if i > 0 {
        i - 1
    } else if i < 0 {
        count as i64 + i
    } else {
        return Err(format!(
            "bad face vertex `{tok}`: OBJ indices start at 1 (0 is not a valid {one} index)"
        ));
    };
    if resolved < 0 || resolved >= count as i64 {
        return Err(format!(
            "{one} index {i} in `{tok}` is out of range: {count} {} defined before this line",
            if count == 1 {
                format!("{one} is")
            } else {
                format!("{many} are")
            }
        ));
    }
    Ok(resolved as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fv(p: u32, uv: Option<u32>, n: Option<u32>) -> FaceVertex {
        FaceVertex {
            position: p,
            normal: n,
            uv,
        }
    }

    #[test]
    fn groups_mark_the_parts_in_face_order() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\ng lens\nf 1 3 2\nf 2 3 1\n\
                    o empty\ng body part\nf 3 2 1\n";
        let m = parse_obj(text, "g.obj", "g.obj").unwrap();
        assert_eq!(m.faces.len(), 4);
        let names: Vec<(&str, u32)> = m
            .groups
            .iter()
            .map(|g| (g.name.as_str(), g.first_face))
            .collect();
        // A group that receives no faces ("empty") is replaced by the next one.
        assert_eq!(names, [("lens", 1), ("body part", 3)]);
    }

    #[test]
    fn quad_fan_and_forms() {
        let text = "# a quad\nmtllib x.mtl\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                    vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 2\ng g1\nusemtl m\ns off\n\
                    f 1/1/1 2/2/1 3/3/1 4/4/1\n";
        let m = parse_obj(text, "q.obj", "q.obj").unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.normals, vec![[0.0, 0.0, 1.0]]);
        assert_eq!(m.uvs[2], [1.0, 1.0]);
        assert_eq!(
            m.faces,
            vec![
                [
                    fv(0, Some(0), Some(0)),
                    fv(1, Some(1), Some(0)),
                    fv(2, Some(2), Some(0))
                ],
                [
                    fv(0, Some(0), Some(0)),
                    fv(2, Some(2), Some(0)),
                    fv(3, Some(3), Some(0))
                ],
            ]
        );
    }

    #[test]
    fn negative_indices_and_double_slash() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf -3//-1 -2//-1 -1//-1\n\
                    v 5 5 5\nf 1 2 -1\nf 1/ 2/ 3/\n";
        let m = parse_obj(text, "n.obj", "n.obj").unwrap();
        assert_eq!(
            m.faces,
            vec![
                [
                    fv(0, None, Some(0)),
                    fv(1, None, Some(0)),
                    fv(2, None, Some(0))
                ],
                [fv(0, None, None), fv(1, None, None), fv(3, None, None)],
                [fv(0, None, None), fv(1, None, None), fv(2, None, None)],
            ]
        );
    }

    #[test]
    fn polygon_with_collinear_vertex_keeps_the_rest() {
        // 1, 2, 3 are collinear: the first fan triangle is dropped, the second kept.
        let text = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 1 1 0\nf 1 2 3 4\n";
        let m = parse_obj(text, "c.obj", "c.obj").unwrap();
        assert_eq!(m.faces.len(), 1);
    }

    fn obj_err(text: &str) -> (Option<usize>, Option<usize>, String) {
        match parse_obj(text, "e.obj", "e.obj").unwrap_err() {
            SceneError::Obj {
                line, col, message, ..
            } => (line, col, message),
            e => panic!("unexpected {e}"),
        }
    }

    #[test]
    fn errors_name_line_and_column() {
        let (l, c, m) = obj_err("v 0 0 0\nv 1 x 0\n");
        assert_eq!((l, c), (Some(2), Some(5)), "{m}");
        assert!(m.contains("expected a number, found `x`"), "{m}");

        let (l, c, m) = obj_err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
        assert_eq!((l, c), (Some(4), Some(7)), "{m}");
        assert!(m.contains("out of range"), "{m}");

        let (l, c, m) = obj_err("v 0 0 0\nv 1 0 0\nf 1 2\n");
        assert_eq!((l, c), (Some(3), Some(1)));
        assert!(m.contains("at least 3 vertices"), "{m}");

        let (l, _, m) = obj_err("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
        assert_eq!(l, Some(4));
        assert!(m.contains("degenerate triangle"), "{m}");

        // Beyond f32 (the vertex became infinite and the face "degenerate"), or a non-zero
        // below the smallest normal f32.
        let (l, c, m) = obj_err("v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n");
        assert_eq!((l, c), (Some(2), Some(3)), "{m}");
        assert_eq!(
            m,
            "expected a number within the f32 range (about ±3.4e38), found `1e39`"
        );
        let (l, c, m) = obj_err("v 0 0 0\nvn 0 -1e-45 1\n");
        assert_eq!((l, c), (Some(2), Some(6)), "{m}");
        assert_eq!(
            m,
            "expected a number of at least about 1.2e-38 in magnitude (a smaller non-zero number \
             underflows f32), found `-1e-45`"
        );
        let (l, c, _) = obj_err("v 0 0 0\nvt 0.5 3.5e38\n");
        assert_eq!((l, c), (Some(2), Some(8)));

        let (l, c, m) = obj_err("v 0 NaN 0\n");
        assert_eq!((l, c), (Some(1), Some(5)));
        assert!(m.contains("finite"), "{m}");

        let (l, c, _) = obj_err("v 0 0 0\n  f 0 1 1\n");
        assert_eq!((l, c), (Some(2), Some(5)));

        let (l, c, m) = obj_err("v 0 0 0\nv 1 0 0\nv 0 1 0\n f 1 2 7\n");
        assert_eq!((l, c), (Some(4), Some(8)));
        assert_eq!(
            m,
            "vertex index 7 in `7` is out of range: 3 vertices are defined before this line"
        );

        let (l, c, _) = obj_err("v 0 0 0\nv 1 0 0\n   f 1 2\n");
        assert_eq!((l, c), (Some(3), Some(4)));

        let (l, c, m) = obj_err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n");
        assert_eq!((l, c), (Some(4), Some(3)));
        assert!(m.contains("out of range"), "{m}");

        let (l, _, m) = obj_err("v 0 0 0\ncurv 0 1 1 2\n");
        assert_eq!(l, Some(2));
        assert!(m.contains("unsupported OBJ statement `curv`"), "{m}");

        let (l, c, m) = obj_err("v 0 0 0\n");
        assert_eq!((l, c), (None, None));
        assert!(m.contains("no faces"), "{m}");
    }
}
