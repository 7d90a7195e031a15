//! The shapes step: each shape of a cluster transformed into view coordinates and written
//! as a record with its leaf node.

use super::*;

/// Where a shape sits: its cluster's transform into view coordinates, the inverse transpose
/// that carries its normals, and the cluster's path (for errors).
struct Place<'p> {
    full: &'p Affine,
    normal_m: M3,
    path: &'p str,
}

impl Dm<'_> {
    pub(super) fn shape(
        &mut self,
        s: &Shape,
        full: &Affine,
        path: &str,
    ) -> Result<Bounds, DmError> {
        let normal_m =
            transpose(
                &inverse(&full.a).ok_or_else(|| DmError::DegenerateTransform {
                    cluster: path.to_string(),
                })?,
            );
        let at = Place {
            full,
            normal_m,
            path,
        };
        match s {
            Shape::Triangle {
                v,
                normals,
                uv,
                material,
            } => self.triangle(v, normals, uv, material, &at),
            Shape::Mesh {
                mesh,
                material,
                smooth,
            } => self.mesh(mesh, material, smooth, &at),
            Shape::Ellipsoid {
                center,
                radii,
                rotate_deg,
                cut,
                material,
            } => self.ellipsoid(center, radii, rotate_deg, cut, material, &at),
            Shape::Box { min, max, material } => self.boxshape(min, max, material, &at),
            Shape::Blobs {
                balls,
                threshold,
                kernel,
                material,
            } => self.blobs(balls, threshold, kernel, material, &at),
        }
    }

    /// One triangle: a leaf (its normals carried by the inverse transpose).
    fn triangle(
        &mut self,
        v: &[[f64; 3]; 3],
        normals: &Option<[[f64; 3]; 3]>,
        uv: &Option<[[f64; 2]; 3]>,
        material: &u32,
        at: &Place<'_>,
    ) -> Result<Bounds, DmError> {
        let (full, normal_m, path) = (at.full, &at.normal_m, at.path);
        let xn = |n: [f64; 3]| normalize(mat_vec(normal_m, n)).map(f32s);
        let material = self.check_material(*material)?;
        let p = v.map(|p| f32s(full.point(p)));
        let n = match normals {
            Some(ns) => {
                let mut out = [[0.0f32; 3]; 3];
                for k in 0..3 {
                    out[k] = xn(ns[k]).ok_or_else(|| DmError::DegenerateShape {
                        cluster: path.to_string(),
                        what: "a triangle vertex normal".into(),
                    })?;
                }
                Some(out)
            }
            None => None,
        };
        let mut tri = TriData {
            p,
            n,
            uv: uv.map(|u| u.map(|q| q.map(|x| x as f32))),
            material,
        };
        tri.keep_winding(full);
        tri.drop_flat_normals();
        self.check_triangle(&tri, path)?;
        self.triangles(vec![tri])
    }
    /// A mesh: a cluster of its triangles, one sub-cluster per group when it has several.
    fn mesh(
        &mut self,
        mesh: &desc::Mesh,
        material: &u32,
        smooth: &bool,
        at: &Place<'_>,
    ) -> Result<Bounds, DmError> {
        let (full, normal_m, path) = (at.full, &at.normal_m, at.path);
        let material = self.check_material(*material)?;
        let mut tris = self.mesh_triangles(mesh, *smooth, material, full, normal_m, path)?;
        let node = self.open_node();
        let b = if mesh.groups.len() <= 1 {
            self.triangles(tris)?
        } else {
            // One sub-cluster per group (the model's parts), last group first so the
            // tail of `tris` can be split off; then written in file order.
            let mut parts = Vec::with_capacity(mesh.groups.len());
            for g in mesh.groups.iter().rev() {
                let at = (g.first_face as usize).min(tris.len());
                parts.push(tris.split_off(at));
            }
            if !tris.is_empty() {
                // Faces before the first group form a part of their own.
                parts.push(tris);
            }
            let mut b = Bounds::empty();
            for part in parts.into_iter().rev().filter(|p| !p.is_empty()) {
                let sub = self.open_node();
                let pb = self.triangles(part)?;
                self.close_node(sub, pb);
                b = b.union(pb);
            }
            b
        };
        self.close_node(node, b);
        Ok(b)
    }
    /// An ellipsoid: the unit sphere under the shape and cluster transforms, its cut plane in unit space.
    fn ellipsoid(
        &mut self,
        center: &[f64; 3],
        radii: &[f64; 3],
        rotate_deg: &[f64; 3],
        cut: &Option<desc::CutPlane>,
        material: &u32,
        at: &Place<'_>,
    ) -> Result<Bounds, DmError> {
        let (full, path) = (at.full, at.path);
        let material = self.check_material(*material)?;
        let obj = Affine::from_trs(*center, *rotate_deg, *radii);
        let m = full.then(&obj);
        let inv = inverse(&m.a).ok_or_else(|| DmError::DegenerateShape {
            cluster: path.to_string(),
            what: "an ellipsoid".into(),
        })?;
        let (flags, cn, cd) = match cut {
            Some(c) => {
                let sn = [
                    c.normal[0] * radii[0],
                    c.normal[1] * radii[1],
                    c.normal[2] * radii[2],
                ];
                let len = dot(sn, sn).sqrt();
                if len == 0.0 || !len.is_finite() {
                    return Err(DmError::DegenerateShape {
                        cluster: path.to_string(),
                        what: "an ellipsoid's cut plane".into(),
                    });
                }
                (
                    1 | (u32::from(c.capped) << 1),
                    sn.map(|v| v / len),
                    c.offset / len,
                )
            }
            None => (0, [0.0; 3], 0.0),
        };
        let (i, r) = self.w.push(Section::Ellipsoids);
        r.fs(ellipsoid::CENTER, &f32s(m.t))
            .fs(ellipsoid::TO_UNIT, &mat_f32(&inv))
            .fs(ellipsoid::TO_VIEW, &mat_f32(&m.a))
            .u(ellipsoid::MATERIAL, material)
            .u(ellipsoid::FLAGS, flags)
            .fs(ellipsoid::CUT_N, &f32s(cn))
            .f(ellipsoid::CUT_D, cd as f32);
        // Half-extent of a transformed unit sphere along axis i: |row i of L|.
        let half = [0, 1, 2].map(|k| dot(m.a[k], m.a[k]).sqrt());
        let b = Bounds::from_f64(sub(m.t, half), add(m.t, half));
        self.leaf(ShapeKind::Ellipsoid, i, b);
        Ok(b)
    }
    /// A box: the cube [-1, 1]^3 under the shape and cluster transforms.
    fn boxshape(
        &mut self,
        min: &[f64; 3],
        max: &[f64; 3],
        material: &u32,
        at: &Place<'_>,
    ) -> Result<Bounds, DmError> {
        let (full, path) = (at.full, at.path);
        let material = self.check_material(*material)?;
        let c = [0, 1, 2].map(|k| 0.5 * (min[k] + max[k]));
        let h = [0, 1, 2].map(|k| 0.5 * (max[k] - min[k]));
        let m = full.then(&Affine { a: diag(h), t: c });
        let inv = inverse(&m.a).ok_or_else(|| DmError::DegenerateShape {
            cluster: path.to_string(),
            what: "a box".into(),
        })?;
        let (i, r) = self.w.push(Section::Boxes);
        r.fs(boxshape::CENTER, &f32s(m.t))
            .fs(boxshape::TO_UNIT, &mat_f32(&inv))
            .fs(boxshape::TO_VIEW, &mat_f32(&m.a))
            .u(boxshape::MATERIAL, material);
        let half = [0, 1, 2].map(|k| m.a[k].iter().map(|v| v.abs()).sum::<f64>());
        let b = Bounds::from_f64(sub(m.t, half), add(m.t, half));
        self.leaf(ShapeKind::Box, i, b);
        Ok(b)
    }
    /// A blob group: its balls (a uniform scale only) and the group record.
    fn blobs(
        &mut self,
        balls: &[desc::Ball],
        threshold: &f64,
        kernel: &desc::BlobKernel,
        material: &u32,
        at: &Place<'_>,
    ) -> Result<Bounds, DmError> {
        let (full, path) = (at.full, at.path);
        let material = self.check_material(*material)?;
        // Uniform scale s: columns of the linear part are orthogonal with equal length.
        let ata = mat_mul(&transpose(&full.a), &full.a);
        let s2 = ata[0][0];
        let tol = 1e-9 * s2;
        let uniform = (0..3)
            .all(|i| (0..3).all(|j| (ata[i][j] - if i == j { s2 } else { 0.0 }).abs() <= tol));
        if !uniform || s2 <= 0.0 {
            return Err(DmError::NonUniformBlobScale {
                cluster: path.to_string(),
            });
        }
        if balls.is_empty() {
            return Err(DmError::DegenerateShape {
                cluster: path.to_string(),
                what: "an empty blob group".into(),
            });
        }
        let s = s2.sqrt();
        let first = self.w.count(Section::Balls);
        let mut lo = [f64::MAX; 3];
        let mut hi = [f64::MIN; 3];
        for ball in balls {
            let c = full.point(ball.center);
            let r = ball.radius * s;
            self.w
                .push(Section::Balls)
                .1
                .fs(ball::CENTER, &f32s(c))
                .f(ball::RADIUS, r as f32)
                .f(ball::STRENGTH, ball.strength as f32);
            if ball.strength > 0.0 {
                for k in 0..3 {
                    lo[k] = lo[k].min(c[k] - r);
                    hi[k] = hi[k].max(c[k] + r);
                }
            }
        }
        let (i, r) = self.w.push(Section::BlobGroups);
        let k = match kernel {
            desc::BlobKernel::Links => 0,
            desc::BlobKernel::Wyvill => 1,
        };
        r.u(blob_group::MATERIAL, material)
            .u(blob_group::KERNEL, k)
            .f(blob_group::THRESHOLD, *threshold as f32)
            .u(blob_group::FIRST, first)
            .u(blob_group::COUNT, balls.len() as u32);
        // Grow by a relative margin: the root finder may stop a tolerance outside.
        let pad = [0, 1, 2].map(|k| 1e-4 * (hi[k] - lo[k]).abs());
        let b = if lo[0] > hi[0] {
            Bounds::empty()
        } else {
            Bounds::from_f64(sub(lo, pad), add(hi, pad))
        };
        self.leaf(ShapeKind::Blob, i, b);
        Ok(b)
    }
}
