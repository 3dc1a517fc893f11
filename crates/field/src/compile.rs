//! Scene tree -> flat [`Program`]: transforms folded into per-node affine maps with their
//! Lipschitz scale, bounding boxes in each parent's frame, repetition windows.

use glam::{DAffine3, DMat3, DVec3};
use marchmesh_scene::{Node, NodeKind};

use crate::FieldError;
use crate::program::{Affine, Instr, MAX_WINDOW, Op, Program};
use crate::shapes::TriData;

/// An axis-aligned box that may hold infinities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Aabb {
    pub lo: DVec3,
    pub hi: DVec3,
}

impl Aabb {
    pub const INFINITE: Aabb = Aabb {
        lo: DVec3::splat(f64::NEG_INFINITY),
        hi: DVec3::splat(f64::INFINITY),
    };
    fn sym(h: DVec3) -> Aabb {
        Aabb { lo: -h, hi: h }
    }
    fn is_finite(&self) -> bool {
        self.lo.is_finite() && self.hi.is_finite()
    }
    fn any_finite(&self) -> bool {
        (0..3).any(|a| self.lo[a].is_finite() || self.hi[a].is_finite())
    }
    fn hull(&self, o: &Aabb) -> Aabb {
        Aabb {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }
    fn intersect(&self, o: &Aabb) -> Aabb {
        Aabb {
            lo: self.lo.max(o.lo),
            hi: self.hi.min(o.hi),
        }
    }
    /// The box containing this box mapped by `xf`.
    fn transformed(&self, xf: &DAffine3) -> Aabb {
        if self.is_finite() {
            let mut lo = DVec3::splat(f64::INFINITY);
            let mut hi = DVec3::splat(f64::NEG_INFINITY);
            for i in 0..8 {
                let c = DVec3::new(
                    if i & 1 == 0 { self.lo.x } else { self.hi.x },
                    if i & 2 == 0 { self.lo.y } else { self.hi.y },
                    if i & 4 == 0 { self.lo.z } else { self.hi.z },
                );
                let w = xf.transform_point3(c);
                lo = lo.min(w);
                hi = hi.max(w);
            }
            Aabb { lo, hi }
        } else if xf.matrix3 == DMat3::IDENTITY {
            Aabb {
                lo: self.lo + xf.translation,
                hi: self.hi + xf.translation,
            }
        } else {
            Aabb::INFINITE
        }
    }
}

/// Smallest singular value of `m` (square root of the smallest eigenvalue of `m^T m`, by
/// cyclic Jacobi rotations).
pub(crate) fn min_singular_value(m: &DMat3) -> f64 {
    let s = m.transpose() * *m;
    let mut a = [
        [s.x_axis.x, s.y_axis.x, s.z_axis.x],
        [s.x_axis.y, s.y_axis.y, s.z_axis.y],
        [s.x_axis.z, s.y_axis.z, s.z_axis.z],
    ];
    for _ in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-30 * (a[0][0].abs() + a[1][1].abs() + a[2][2].abs()) {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * c;
            // a <- J^T a J with the rotation in the (p, q) plane.
            for k in 0..3 {
                let akp = a[k][p];
                let akq = a[k][q];
                a[k][p] = c * akp - sn * akq;
                a[k][q] = sn * akp + c * akq;
            }
            for k in 0..3 {
                let apk = a[p][k];
                let aqk = a[q][k];
                a[p][k] = c * apk - sn * aqk;
                a[q][k] = sn * apk + c * aqk;
            }
        }
    }
    let l = a[0][0].min(a[1][1]).min(a[2][2]).max(0.0);
    l.sqrt()
}

/// A mesh the compiler needs a grid for; the caller resolves it.
pub(crate) trait MeshResolver {
    /// Grid index and the mesh's solid bounds in its local frame.
    fn resolve(&mut self, node: &Node) -> Result<(u32, Aabb), FieldError>;
}

pub(crate) struct Compiler<'a> {
    pub instrs: Vec<Instr<f64>>,
    pub notes: Vec<String>,
    pub meshes: &'a mut dyn MeshResolver,
}

fn a3(v: DVec3) -> [f64; 3] {
    v.to_array()
}

impl Compiler<'_> {
    /// Compiles `n` with `xf` = node frame -> program parent frame. Returns its box in the
    /// parent frame.
    pub fn node(&mut self, n: &Node, xf: DAffine3) -> Result<Aabb, FieldError> {
        let inv = xf.inverse();
        let dscale = min_singular_value(&xf.matrix3);
        if !inv.is_finite()
            || dscale.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
            || !dscale.is_finite()
        {
            return Err(FieldError::Degenerate {
                json_path: n.json_path.clone(),
                reason: "transform is singular or not finite".into(),
            });
        }
        if (dscale - 1.0).abs() > 1e-9 {
            let m = xf.matrix3;
            let big = m
                .x_axis
                .length()
                .max(m.y_axis.length())
                .max(m.z_axis.length());
            if big - dscale > 1e-9 * big {
                self.notes.push(format!(
                    "{}: non-uniform scale, distances multiplied by the smallest singular value {dscale:.4} (a bound)",
                    n.json_path
                ));
            }
        }
        let idx = self.instrs.len();
        let lin = if inv.matrix3 == DMat3::IDENTITY {
            None
        } else {
            let m = inv.matrix3.transpose(); // rows of inv = columns of its transpose
            Some([
                m.x_axis.x, m.x_axis.y, m.x_axis.z, m.y_axis.x, m.y_axis.y, m.y_axis.z, m.z_axis.x,
                m.z_axis.y, m.z_axis.z,
            ])
        };
        self.instrs.push(Instr {
            end: 0,
            material: n.material,
            has_bound: false,
            lo: [0.0; 3],
            hi: [0.0; 3],
            tau: 0.0,
            to_local: Affine {
                lin,
                trans: a3(inv.translation),
            },
            dscale,
            op: Op::Union,
        });
        let (op, local) = match &n.kind {
            NodeKind::Sphere { radius } => {
                let m = xf.matrix3;
                let sc = m.x_axis.length();
                let g = m.transpose() * m;
                let conformal = (0..3).all(|c| {
                    (0..3).all(|r| {
                        let want = if c == r { sc * sc } else { 0.0 };
                        (g.col(c)[r] - want).abs() <= 1e-12 * sc * sc
                    })
                });
                let c = xf.translation;
                let r = radius * sc;
                // Only when the frame origin (the camera, in render space) is close to the
                // surface relative to the radius does `|p - c| - r` lose precision in f32.
                if conformal && r >= 16.0 * (c.length() - r).abs() {
                    // Rotation and uniform scale: a sphere in the parent frame, evaluated
                    // without moving the point into the local frame first (see Op::SphereAt).
                    self.instrs[idx].evaluate_in_parent_frame();
                    (
                        Op::SphereAt {
                            c: a3(c),
                            r,
                            k: (c.length_squared() - r * r),
                        },
                        Aabb::sym(DVec3::splat(*radius)),
                    )
                } else {
                    (Op::Sphere { r: *radius }, Aabb::sym(DVec3::splat(*radius)))
                }
            }
            NodeKind::Plane { normal, offset } => {
                // A plane stays a plane under any affine map: express it in the parent frame
                // in f64 (`n.(A x + b) = offset`) and evaluate it there, exactly. Moving the
                // point into the local frame in f32 instead would add the camera's world
                // position back (1e5 units away: 0.008-unit rounding, step exhaustion).
                let a = inv.matrix3;
                let n_parent = a.transpose() * *normal;
                let len = n_parent.length();
                let offset_parent = (offset - normal.dot(inv.translation)) / len;
                self.instrs[idx].evaluate_in_parent_frame();
                (
                    Op::Plane {
                        n: a3(n_parent / len),
                        offset: offset_parent,
                    },
                    Aabb::INFINITE,
                )
            }
            NodeKind::Box { half_extents } => (
                Op::Box {
                    b: a3(*half_extents),
                },
                Aabb::sym(*half_extents),
            ),
            NodeKind::Ellipsoid { radii } => (
                Op::Ellipsoid {
                    inv_r: a3(radii.recip()),
                    rmin: radii.min_element(),
                },
                Aabb::sym(*radii),
            ),
            NodeKind::Cylinder {
                radius,
                half_height,
            } => (
                Op::Cylinder {
                    r: *radius,
                    h: *half_height,
                },
                Aabb::sym(DVec3::new(*radius, *half_height, *radius)),
            ),
            NodeKind::Torus {
                major_radius,
                minor_radius,
            } => {
                let o = major_radius + minor_radius;
                (
                    Op::Torus {
                        big: *major_radius,
                        small: *minor_radius,
                    },
                    Aabb::sym(DVec3::new(o, *minor_radius, o)),
                )
            }
            NodeKind::Triangle { vertices } => {
                let [a, b, c] = *vertices;
                let (ba, cb, ac) = (b - a, c - b, a - c);
                let nor = ba.cross(ac);
                if nor.length_squared().partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                    return Err(FieldError::Degenerate {
                        json_path: n.json_path.clone(),
                        reason: "triangle has collinear vertices".into(),
                    });
                }
                let t = TriData {
                    a: a3(a),
                    b: a3(b),
                    c: a3(c),
                    ba: a3(ba),
                    cb: a3(cb),
                    ac: a3(ac),
                    en: [a3(ba.cross(nor)), a3(cb.cross(nor)), a3(ac.cross(nor))],
                    n: a3(nor.normalize()),
                    inv2: [
                        1.0 / ba.length_squared(),
                        1.0 / cb.length_squared(),
                        1.0 / ac.length_squared(),
                    ],
                };
                (
                    Op::Triangle(Box::new(t)),
                    Aabb {
                        lo: a.min(b).min(c),
                        hi: a.max(b).max(c),
                    },
                )
            }
            NodeKind::Mesh { .. } => {
                let (grid, bb) = self.meshes.resolve(n)?;
                (Op::Mesh { grid }, bb)
            }
            NodeKind::Union(ch) if ch.len() > GROUP => {
                let items: Vec<(&Node, DAffine3)> = ch.iter().map(|c| (c, c.transform)).collect();
                (Op::Union, self.grouped_union(&items)?)
            }
            NodeKind::Union(ch) | NodeKind::Intersection(ch) | NodeKind::Subtraction(ch) => {
                let boxes = self.children(ch)?;
                let op = match &n.kind {
                    NodeKind::Union(_) => Op::Union,
                    NodeKind::Intersection(_) => Op::Intersection,
                    _ => Op::Subtraction,
                };
                let bb = match op {
                    Op::Union => boxes.iter().skip(1).fold(boxes[0], |a, b| a.hull(b)),
                    Op::Intersection => boxes.iter().skip(1).fold(boxes[0], |a, b| a.intersect(b)),
                    _ => boxes[0],
                };
                (op, bb)
            }
            NodeKind::SmoothUnion {
                children,
                blend_radius,
            } => {
                let boxes = self.children(children)?;
                let hull = boxes.iter().skip(1).fold(boxes[0], |a, b| a.hull(b));
                // Each fold lowers the value by at most k/4 below the children's minimum.
                let grow = blend_radius * 0.25 * (children.len().saturating_sub(1)) as f64;
                (
                    Op::SmoothUnion {
                        k: *blend_radius,
                        inv_k: 1.0 / blend_radius,
                    },
                    Aabb {
                        lo: hull.lo - DVec3::splat(grow),
                        hi: hull.hi + DVec3::splat(grow),
                    },
                )
            }
            NodeKind::Repeat {
                child,
                period,
                count,
            } => {
                let cb = self.node(child, child.transform)?;
                let mut bb = cb;
                let mut cnt = [0.0; 3];
                let mut first = [0.0; 3];
                let mut r = f64::INFINITY;
                for a in 0..3 {
                    if period[a] > 0.0 {
                        r = r.min(period[a] * 0.5);
                    }
                }
                let mut exact = true;
                for a in 0..3 {
                    let p = period[a];
                    if p <= 0.0 {
                        continue;
                    }
                    let w = cb.hi[a] - cb.lo[a];
                    let rmax = ((MAX_WINDOW - 1) as f64 * p - w) * 0.5;
                    if w.is_finite() && rmax > 1e-3 * p {
                        r = r.min(rmax);
                    } else {
                        exact = false;
                    }
                    match count[a] {
                        Some(c) => {
                            cnt[a] = c as f64;
                            first[a] = -(c as f64 - 1.0) * 0.5 * p;
                            bb.lo[a] = cb.lo[a] + first[a];
                            bb.hi[a] = cb.hi[a] - first[a];
                        }
                        None => {
                            bb.lo[a] = f64::NEG_INFINITY;
                            bb.hi[a] = f64::INFINITY;
                        }
                    }
                }
                if !r.is_finite() {
                    r = 1e30;
                }
                if !exact {
                    self.notes.push(format!(
                        "{}: repeated child is wider than {} periods (or unbounded) along a repeated axis; only the nearest {} copies per axis are evaluated and the distance may over-estimate",
                        n.json_path,
                        MAX_WINDOW - 1,
                        MAX_WINDOW
                    ));
                }
                (
                    Op::Repeat {
                        period: a3(*period),
                        count: cnt,
                        first,
                        r,
                    },
                    bb,
                )
            }
        };
        let parent_box = local.transformed(&xf);
        let cheap = matches!(
            op,
            Op::Sphere { .. } | Op::SphereAt { .. } | Op::Box { .. } | Op::Plane { .. }
        );
        let end = self.instrs.len() as u32;
        let ins = &mut self.instrs[idx];
        ins.op = op;
        ins.end = end;
        ins.lo = a3(parent_box.lo);
        ins.hi = a3(parent_box.hi);
        ins.has_bound = !cheap && parent_box.any_finite();
        let leaf = !matches!(
            ins.op,
            Op::Union
                | Op::Intersection
                | Op::Subtraction
                | Op::SmoothUnion { .. }
                | Op::Repeat { .. }
        );
        // Leaves keep only the exact skips (their value is >= the box distance anyway), so
        // exact primitives stay exact everywhere; subtrees switch to their box beyond tau.
        ins.tau = if leaf && !matches!(ins.op, Op::Mesh { .. }) {
            f64::INFINITY
        } else if parent_box.is_finite() {
            ((parent_box.hi - parent_box.lo).length() * 0.5).max(1e-30)
        } else {
            f64::INFINITY
        };
        Ok(parent_box)
    }

    fn children(&mut self, ch: &[Node]) -> Result<Vec<Aabb>, FieldError> {
        ch.iter().map(|c| self.node(c, c.transform)).collect()
    }

    /// Emits the children of a union with many members under a hierarchy of synthetic
    /// identity unions (median splits of the box centres, at most [`GROUP`] members each),
    /// so a point far from a group pays one box test for it. Union is associative and the
    /// synthetic nodes use only the exact skip (infinite tau): values are unchanged.
    /// Members with unbounded boxes (planes, infinite repetition) stay at the top. Returns
    /// the hull of all members.
    fn grouped_union(&mut self, items: &[(&Node, DAffine3)]) -> Result<Aabb, FieldError> {
        let mut compiled: Vec<(Vec<Instr<f64>>, Aabb)> = Vec::with_capacity(items.len());
        for (n, xf) in items {
            let mut sub = Compiler {
                instrs: Vec::new(),
                notes: Vec::new(),
                meshes: &mut *self.meshes,
            };
            let b = sub.node(n, *xf)?;
            self.notes.append(&mut sub.notes);
            compiled.push((sub.instrs, b));
        }
        let hull = compiled
            .iter()
            .skip(1)
            .fold(compiled[0].1, |a, c| a.hull(&c.1));
        let (finite, unbounded): (Vec<_>, Vec<_>) =
            compiled.into_iter().partition(|c| c.1.is_finite());
        for c in unbounded {
            self.splice(c.0);
        }
        self.emit_group(finite);
        Ok(hull)
    }

    fn splice(&mut self, instrs: Vec<Instr<f64>>) {
        let off = self.instrs.len() as u32;
        self.instrs.extend(instrs.into_iter().map(|mut i| {
            i.end += off;
            i
        }));
    }

    fn emit_group(&mut self, mut items: Vec<(Vec<Instr<f64>>, Aabb)>) {
        if items.len() <= GROUP {
            for (instrs, _) in items {
                self.splice(instrs);
            }
            return;
        }
        let hull = items.iter().skip(1).fold(items[0].1, |a, c| a.hull(&c.1));
        let idx = self.instrs.len();
        self.instrs.push(Instr {
            end: 0,
            material: items[0].0[0].material,
            has_bound: true,
            lo: a3(hull.lo),
            hi: a3(hull.hi),
            tau: f64::INFINITY,
            to_local: Affine {
                lin: None,
                trans: [0.0; 3],
            },
            dscale: 1.0,
            op: Op::Union,
        });
        let ext = hull.hi - hull.lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        items.sort_by(|a, b| {
            let ca = a.1.lo[axis] + a.1.hi[axis];
            let cb = b.1.lo[axis] + b.1.hi[axis];
            ca.total_cmp(&cb)
        });
        let right = items.split_off(items.len() / 2);
        self.emit_group(items);
        self.emit_group(right);
        self.instrs[idx].end = self.instrs.len() as u32;
    }
}

/// Most members of one union node before a hierarchy is built over them.
pub const GROUP: usize = 8;

/// Builds the program for `nodes` (each with `xf(node)` as its node->frame transform) under
/// an identity union root; a single node compiles without the root.
pub(crate) type Compiled = (Program<f64>, Option<Aabb>, Vec<String>);

pub(crate) fn compile_roots(
    nodes: &[(&Node, DAffine3)],
    meshes: &mut dyn MeshResolver,
) -> Result<Compiled, FieldError> {
    let mut c = Compiler {
        instrs: Vec::new(),
        notes: Vec::new(),
        meshes,
    };
    let bb = match nodes {
        [] => None,
        [(n, xf)] => Some(c.node(n, *xf)?),
        _ => {
            c.instrs.push(Instr {
                end: 0,
                material: nodes[0].0.material,
                has_bound: false,
                lo: [0.0; 3],
                hi: [0.0; 3],
                tau: f64::INFINITY,
                to_local: Affine {
                    lin: None,
                    trans: [0.0; 3],
                },
                dscale: 1.0,
                op: Op::Union,
            });
            let h = if nodes.len() > GROUP {
                c.grouped_union(nodes)?
            } else {
                let mut hull: Option<Aabb> = None;
                for (n, xf) in nodes {
                    let b = c.node(n, *xf)?;
                    hull = Some(hull.map_or(b, |h| h.hull(&b)));
                }
                hull.expect("at least two roots")
            };
            let end = c.instrs.len() as u32;
            let root = &mut c.instrs[0];
            root.end = end;
            root.lo = a3(h.lo);
            root.hi = a3(h.hi);
            root.has_bound = h.any_finite();
            root.tau = if h.is_finite() {
                ((h.hi - h.lo).length() * 0.5).max(1e-30)
            } else {
                f64::INFINITY
            };
            Some(h)
        }
    };
    Ok((Program { instrs: c.instrs }, bb, c.notes))
}
