//! Tessellation of the analytic shapes into indexed triangle meshes in the shape's local frame.
//!
//! Curved shapes are surfaces of revolution (sphere, cylinder, torus) or a scaled sphere
//! (ellipsoid) sampled on a tensor-product parameter grid. The step in each direction comes
//! from the chord-error bound of linear interpolation: a curve with `|p''| <= M` per unit
//! parameter, sampled every `h`, deviates from its chords by at most `M h^2 / 8`; each grid
//! direction gets half the budget, so a triangle's error stays within the whole budget.
//! With a constant budget the grid is uniform; with a screen-space budget
//! ([`Detail::Screen`]) each band of the grid gets the budget of its own nearest distance to
//! the camera, so the grid is dense near the camera and sparse far away (a tensor grid stays
//! watertight: no T-junctions).
//! Closed shapes come out watertight (every edge shared by two triangles once vertices at the
//! same position are identified; caps and sides keep separate vertices for their normals),
//! counter-clockwise seen from outside.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

use glam::DVec3;
use marchmesh_scene::{NodeKind, Shape};

/// An indexed triangle mesh in a shape's local frame (f64, converted to f32 once placed).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LocalMesh {
    /// Vertex positions, local units.
    pub positions: Vec<DVec3>,
    /// Unit outward vertex normals (same length as `positions`), or `None` for flat faces.
    pub normals: Option<Vec<DVec3>>,
    /// Counter-clockwise (seen from outside) triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Whether the exact surface is closed (the tessellation then is too).
    pub closed: bool,
    /// Segments per full turn used for each curved direction (empty for flat shapes).
    pub segments: Vec<u32>,
    /// Material per triangle (surfaces extracted from CSG); `None`: the placement's.
    pub materials: Option<Vec<marchmesh_scene::MaterialId>>,
}

/// How fine a tessellation must be, in the shape's local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Detail<'a> {
    /// Largest chord error in local units (> 0), everywhere.
    ChordError(f64),
    /// `8 * 2^level` segments per full turn.
    Level(u32),
    /// A chord error that depends on where a part of the surface is: see [`ScreenBudget`].
    Screen(&'a ScreenBudget),
}

/// A screen-space error budget: a part of the surface inside a local region may deviate by
/// `error_per_distance * max(distance(camera, region), min_distance) / stretch` local units,
/// the smallest over every placement of the shape, where distances are world units (render
/// space, camera at the origin) bounded below by the local distance times the placement's
/// smallest stretch, and `stretch` is its largest.
#[derive(Debug, Clone, PartialEq)]
pub struct ScreenBudget {
    placements: Vec<Placed>,
    error_per_distance: f64,
    min_distance: f64,
}

/// One placement as the budget needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Placed {
    /// The camera in the shape's local frame.
    camera: DVec3,
    /// Smallest and largest singular values of the object-to-render linear part.
    stretch_min: f64,
    stretch_max: f64,
}

impl ScreenBudget {
    /// A budget for a shape placed by `placements` (object-to-render transforms), allowing
    /// `error_per_distance` (`pixels * camera.pixel_angle()`) world units of chord error per
    /// unit of camera distance, distances floored at `min_distance` (world units).
    pub fn new(placements: &[glam::DAffine3], error_per_distance: f64, min_distance: f64) -> Self {
        Self {
            placements: placements
                .iter()
                .map(|m| {
                    let inverse = m.inverse();
                    Placed {
                        camera: inverse.transform_point3(DVec3::ZERO),
                        stretch_min: 1.0 / crate::build::max_stretch(&inverse.matrix3),
                        stretch_max: crate::build::max_stretch(&m.matrix3),
                    }
                })
                .collect(),
            error_per_distance,
            min_distance,
        }
    }

    /// The same budget in a frame where local points are `scale * p` (e.g. a unit sphere
    /// standing for an ellipsoid): errors come out in that frame's units.
    pub fn scaled(&self, scale: DVec3) -> Self {
        let (lo, hi) = (scale.min_element(), scale.max_element());
        Self {
            placements: self
                .placements
                .iter()
                .map(|p| Placed {
                    camera: p.camera / scale,
                    stretch_min: p.stretch_min * lo,
                    stretch_max: p.stretch_max * hi,
                })
                .collect(),
            ..self.clone()
        }
    }

    fn error_at(&self, local_distance: impl Fn(DVec3) -> f64) -> f64 {
        self.placements
            .iter()
            .map(|p| {
                let d = (local_distance(p.camera) * p.stretch_min).max(self.min_distance);
                self.error_per_distance * d / p.stretch_max
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The local chord error allowed for the part of the surface inside `local_box`
    /// (infinite when there is no placement).
    pub fn local_error(&self, (lo, hi): (DVec3, DVec3)) -> f64 {
        self.error_at(|c| (lo - c).max(c - hi).max(DVec3::ZERO).length())
    }

    /// The local chord error allowed for the part of the surface inside the solid of
    /// revolution about y with radius in `radial` and height in `y`.
    fn ring_error(&self, radial: (f64, f64), y: (f64, f64)) -> f64 {
        self.error_at(|c| {
            let rho = glam::DVec2::new(c.x, c.z).length();
            let dr = (radial.0 - rho).max(rho - radial.1).max(0.0);
            let dy = (y.0 - c.y).max(c.y - y.1).max(0.0);
            (dr * dr + dy * dy).sqrt()
        })
    }
}

/// Segments for a direction spanning `fraction` of a full turn whose points move with
/// second derivative at most `curvature_bound` per radian; clamped to
/// `[min, max_per_turn * fraction]`.
pub fn segments(
    detail: Detail,
    curvature_bound: f64,
    fraction: f64,
    min: u32,
    max_per_turn: u32,
) -> u32 {
    let max = ((f64::from(max_per_turn) * fraction).ceil() as u32).max(min);
    let n = match detail {
        // The coarsest screen budget is the one of the whole shape.
        Detail::Screen(_) => return min,
        Detail::ChordError(e) => {
            if e.is_nan() || e <= 0.0 || curvature_bound.is_nan() || curvature_bound <= 0.0 {
                return max;
            }
            // Half the budget per direction: M h^2 / 8 <= e / 2  =>  h = 2 sqrt(e / M).
            let h = 2.0 * (e / curvature_bound).sqrt();
            let n = (TAU * fraction / h).ceil();
            if n.is_finite() {
                n.min(f64::from(u32::MAX)) as u32
            } else {
                max
            }
        }
        Detail::Level(level) => {
            let per_turn = 8u64 << level.min(24);
            (per_turn as f64 * fraction).round() as u32
        }
    };
    n.clamp(min, max)
}

/// One point of a revolution profile in the (radial, y) half plane.
#[derive(Debug, Clone, Copy)]
struct ProfilePoint {
    radial: f64,
    y: f64,
    /// Outward unit normal (radial, y).
    normal: (f64, f64),
    /// On the axis: one vertex instead of a ring.
    pole: bool,
}

/// Revolves profile polylines about the y axis at the angles `phi` (increasing, in
/// `[0, 2 pi)`, at least 3), counter-clockwise from outside when each polyline runs so that
/// `(-dy, dr)` points outward. A `closed` polyline connects its last point back to its first.
fn revolve(
    pieces: &[(Vec<ProfilePoint>, bool)],
    phi: &[f64],
    mesh: &mut LocalMesh,
    max_triangles: u64,
) -> Result<(), TooManyTriangles> {
    // Count first, allocate after: a camera touching a shape can ask for billions.
    let planned = revolve_triangle_count(pieces, phi.len()) + mesh.triangles.len() as u64;
    if planned > max_triangles {
        return Err(TooManyTriangles {
            triangles: planned,
            segments: mesh.segments.clone(),
        });
    }
    let n = phi.len() as u32;
    let (sin, cos): (Vec<f64>, Vec<f64>) = phi.iter().map(|a| a.sin_cos()).unzip();
    let normals = mesh.normals.get_or_insert_with(Vec::new);
    for (profile, closed) in pieces {
        // First vertex index of each profile row, whether it is a pole (one triangle per
        // segment meets it) and whether it is a ring of vertices at an apex.
        let mut rows: Vec<(u32, bool, bool)> = Vec::with_capacity(profile.len());
        for p in profile {
            let start = mesh.positions.len() as u32;
            if p.pole && p.normal.0 == 0.0 {
                mesh.positions.push(DVec3::new(0.0, p.y, 0.0));
                normals.push(DVec3::new(0.0, p.normal.1.signum(), 0.0));
            } else {
                // A ring of vertices; at an apex (a pole with a slanted normal, a cone's tip)
                // they share the point, so each triangle meeting there keeps its own normal.
                for j in 0..n as usize {
                    mesh.positions
                        .push(DVec3::new(p.radial * cos[j], p.y, p.radial * sin[j]));
                    normals.push(DVec3::new(
                        p.normal.0 * cos[j],
                        p.normal.1,
                        p.normal.0 * sin[j],
                    ));
                }
            }
            rows.push((start, p.pole, p.pole && p.normal.0 != 0.0));
        }
        let count = rows.len();
        let bands = if *closed {
            count
        } else {
            count.saturating_sub(1)
        };
        for k in 0..bands {
            let (top, top_pole, top_ring) = rows[k];
            let (bottom, bottom_pole, bottom_ring) = rows[(k + 1) % count];
            let at = |start: u32, pole: bool, ring: bool, j: u32| {
                if pole && !ring { start } else { start + j % n }
            };
            for j in 0..n {
                let a = at(top, top_pole, top_ring, j);
                let b = at(top, top_pole, top_ring, j + 1);
                let c = at(bottom, bottom_pole, bottom_ring, j);
                let d = at(bottom, bottom_pole, bottom_ring, j + 1);
                if !top_pole {
                    mesh.triangles.push([a, b, c]);
                }
                if !bottom_pole {
                    mesh.triangles.push([b, d, c]);
                }
            }
        }
    }
    Ok(())
}

/// Triangles [`revolve`] makes of `pieces` at `n` angles (an upper bound: rows at a pole make
/// one triangle per segment, not two).
fn revolve_triangle_count(pieces: &[(Vec<ProfilePoint>, bool)], n: usize) -> u64 {
    pieces
        .iter()
        .map(|(profile, closed)| {
            let bands = if *closed {
                profile.len()
            } else {
                profile.len().saturating_sub(1)
            };
            2 * bands as u64 * n as u64
        })
        .sum()
}

/// A tessellation would make more triangles than allowed ([`tessellate_within`]); nothing
/// was allocated for them.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the tessellation would make {triangles} triangles (segments per turn {segments:?})")]
pub struct TooManyTriangles {
    /// Triangles the tessellation would make.
    pub triangles: u64,
    /// Segments per turn of each parametric direction chosen so far.
    pub segments: Vec<u32>,
}

/// `(min, max)` of `f` over `[a, b]`, `f` being a sinusoid with its extremes at
/// `phase + k pi`.
fn trig_range(a: f64, b: f64, f: fn(f64) -> f64, phase: f64) -> (f64, f64) {
    let mut lo = f(a).min(f(b));
    let mut hi = f(a).max(f(b));
    let mut k = ((a - phase) / PI).ceil();
    while phase + k * PI <= b {
        let v = f(phase + k * PI);
        lo = lo.min(v);
        hi = hi.max(v);
        k += 1.0;
    }
    (lo, hi)
}

fn cos_range(a: f64, b: f64) -> (f64, f64) {
    trig_range(a, b, f64::cos, 0.0)
}

fn sin_range(a: f64, b: f64) -> (f64, f64) {
    trig_range(a, b, f64::sin, FRAC_PI_2)
}

/// Range of the product of two intervals.
fn mul_range((a, b): (f64, f64), (c, d): (f64, f64)) -> (f64, f64) {
    let p = [a * c, a * d, b * c, b * d];
    (
        p.iter().copied().fold(f64::INFINITY, f64::min),
        p.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    )
}

/// Local box of the wedge `phi in [a, b]` of a surface of revolution with radial range
/// `radial` and height range `y`.
fn wedge_box(a: f64, b: f64, radial: (f64, f64), y: (f64, f64)) -> (DVec3, DVec3) {
    let x = mul_range(radial, cos_range(a, b));
    let z = mul_range(radial, sin_range(a, b));
    (DVec3::new(x.0, y.0, z.0), DVec3::new(x.1, y.1, z.1))
}

/// Parameter samples from `start` to `end` (both included). Constant budgets give a
/// uniform grid whose step keeps `curvature_bound h^2 / 8` within half the budget; a screen
/// budget marches with `max_step(a, b)`, the largest step allowed for the interval `[a, b]`.
/// Steps never go below `2 pi / max_per_turn`; at least `min` segments.
fn sample_span(
    detail: Detail,
    (start, end): (f64, f64),
    curvature_bound: f64,
    min: u32,
    max_per_turn: u32,
    max_step: impl Fn(f64, f64) -> f64,
) -> Vec<f64> {
    let span = end - start;
    let uniform = |n: u32| -> Vec<f64> {
        let n = n.max(1);
        (0..=n)
            .map(|i| {
                if i == n {
                    end
                } else {
                    start + span * f64::from(i) / f64::from(n)
                }
            })
            .collect()
    };
    if !matches!(detail, Detail::Screen(_)) {
        return uniform(segments(
            detail,
            curvature_bound,
            span / TAU,
            min,
            max_per_turn,
        ));
    }
    let h_min = TAU / f64::from(max_per_turn.max(1));
    let allowed = |a: f64, b: f64| {
        let h = max_step(a, b);
        if h.is_nan() { h_min } else { h.max(h_min) }
    };
    let mut out = vec![start];
    let mut s = start;
    while s < end {
        let remaining = end - s;
        // Guess from a thin interval, then re-check the interval the guess spans (its
        // distance can only be smaller, so the second step is the safe one).
        let guess = allowed(s, (s + h_min).min(end)).min(remaining);
        let h = allowed(s, s + guess).min(guess);
        s = if remaining - h <= remaining * 1e-9 {
            end
        } else {
            s + h
        };
        out.push(s);
    }
    if out.len() <= min as usize {
        return uniform(min);
    }
    out
}

/// The step allowed by a chord budget `e` for a curve with second derivative at most `m`:
/// `m h^2 / 8 <= e / 2`.
fn step_for(e: f64, m: f64) -> f64 {
    if m <= 0.0 || e.is_infinite() {
        f64::INFINITY
    } else {
        2.0 * (e.max(0.0) / m).sqrt()
    }
}

/// A band of a revolution profile between two samples: radial and height ranges.
#[derive(Debug, Clone, Copy)]
struct Band {
    radial: (f64, f64),
    y: (f64, f64),
}

/// Merges consecutive bands so that at most `max` remain (conservative unions).
fn coarsen(bands: Vec<Band>, max: usize) -> Vec<Band> {
    if bands.len() <= max {
        return bands;
    }
    let per = bands.len().div_ceil(max);
    bands
        .chunks(per)
        .map(|c| {
            c.iter().fold(
                Band {
                    radial: (f64::INFINITY, f64::NEG_INFINITY),
                    y: (f64::INFINITY, f64::NEG_INFINITY),
                },
                |acc, b| Band {
                    radial: (acc.radial.0.min(b.radial.0), acc.radial.1.max(b.radial.1)),
                    y: (acc.y.0.min(b.y.0), acc.y.1.max(b.y.1)),
                },
            )
        })
        .collect()
}

/// Angles of a full turn for a surface of revolution made of `bands`, each band's wedge
/// getting the budget of its own distance: the step must hold for every band, whose points
/// move by at most `radial` per radian squared.
fn revolution_angles(detail: Detail, bands: &[Band], min: u32, max_per_turn: u32) -> Vec<f64> {
    let radial_max = bands.iter().map(|b| b.radial.1).fold(0.0, f64::max);
    let bands = coarsen(bands.to_vec(), 64);
    turn(sample_span(
        detail,
        (0.0, TAU),
        radial_max,
        min,
        max_per_turn,
        |a, b| {
            let Detail::Screen(budget) = detail else {
                return f64::INFINITY;
            };
            bands
                .iter()
                .map(|band| {
                    step_for(
                        budget.local_error(wedge_box(a, b, band.radial, band.y)),
                        band.radial.1,
                    )
                })
                .fold(f64::INFINITY, f64::min)
        },
    ))
}

/// Angles `phi` of a full turn (without the closing `2 pi`).
fn turn(samples: Vec<f64>) -> Vec<f64> {
    let mut s = samples;
    s.pop();
    s
}

/// An ellipsoid with semi-axes `radii` (a sphere when they are equal) as a latitude-longitude
/// grid with single-vertex poles.
fn lat_long(
    radii: DVec3,
    detail: Detail,
    max_per_turn: u32,
    max_triangles: u64,
) -> Result<LocalMesh, TooManyTriangles> {
    // Work on the unit sphere (second derivatives <= 1 per radian in both directions), with
    // budgets converted to its frame.
    let scaled_budget;
    let detail = match detail {
        Detail::ChordError(e) => Detail::ChordError(e / radii.max_element()),
        Detail::Screen(b) => {
            scaled_budget = b.scaled(radii);
            Detail::Screen(&scaled_budget)
        }
        level => level,
    };
    let theta = sample_span(detail, (0.0, PI), 1.0, 2, max_per_turn, |a, b| {
        let Detail::Screen(budget) = detail else {
            return f64::INFINITY;
        };
        step_for(budget.ring_error(sin_range(a, b), cos_range(a, b)), 1.0)
    });
    let bands: Vec<Band> = theta
        .windows(2)
        .map(|w| Band {
            radial: sin_range(w[0], w[1]),
            y: cos_range(w[0], w[1]),
        })
        .collect();
    let phi = revolution_angles(detail, &bands, 3, max_per_turn);
    let last = theta.len() - 1;
    let profile: Vec<ProfilePoint> = theta
        .iter()
        .enumerate()
        .map(|(k, &t)| {
            let pole = k == 0 || k == last;
            let (s, c) = t.sin_cos();
            let y = if k == 0 {
                1.0
            } else if k == last {
                -1.0
            } else {
                c
            };
            ProfilePoint {
                radial: if pole { 0.0 } else { s },
                y,
                normal: (if pole { 0.0 } else { s }, y),
                pole,
            }
        })
        .collect();
    let mut mesh = LocalMesh {
        closed: true,
        segments: vec![phi.len() as u32, 2 * last as u32],
        ..LocalMesh::default()
    };
    revolve(&[(profile, false)], &phi, &mut mesh, max_triangles)?;
    for p in &mut mesh.positions {
        *p *= radii;
    }
    if let Some(normals) = &mut mesh.normals {
        for n in normals.iter_mut() {
            *n = (*n / radii).normalize();
        }
    }
    Ok(mesh)
}

/// Tessellates an analytic shape (`Sphere`, `Ellipsoid`, `Box`, `Cylinder`, `Torus`,
/// `Triangle`) in its local frame. Returns `None` for shapes without a finite local
/// tessellation (plane, mesh, composites). No triangle cap: see [`tessellate_within`].
pub fn tessellate(kind: &NodeKind, detail: Detail, max_per_turn: u32) -> Option<LocalMesh> {
    // Without a cap the tessellation cannot be refused.
    tessellate_within(kind, detail, max_per_turn, u64::MAX)
        .ok()
        .flatten()
}

/// [`tessellate`] refusing, before allocating them, tessellations of more than
/// `max_triangles` triangles.
///
/// Errors: [`TooManyTriangles`] with the count the tessellation would have made.
pub fn tessellate_within(
    kind: &NodeKind,
    detail: Detail,
    max_per_turn: u32,
    max_triangles: u64,
) -> Result<Option<LocalMesh>, TooManyTriangles> {
    let NodeKind::Leaf(shape) = kind else {
        return Ok(None);
    };
    let mesh = match *shape {
        Shape::Sphere { radius } => {
            lat_long(DVec3::splat(radius), detail, max_per_turn, max_triangles)?
        }
        Shape::Ellipsoid { radii } => lat_long(radii, detail, max_per_turn, max_triangles)?,
        Shape::Cylinder {
            radius,
            half_height,
        } => {
            let h = half_height;
            let bands = [Band {
                radial: (0.0, radius),
                y: (-h, h),
            }];
            let phi = revolution_angles(detail, &bands, 3, max_per_turn);
            let rim = |y: f64, normal: (f64, f64)| ProfilePoint {
                radial: radius,
                y,
                normal,
                pole: false,
            };
            let centre = |y: f64| ProfilePoint {
                radial: 0.0,
                y,
                normal: (0.0, y.signum()),
                pole: true,
            };
            let mut m = LocalMesh {
                closed: true,
                segments: vec![phi.len() as u32],
                ..LocalMesh::default()
            };
            revolve(
                &[
                    (vec![centre(h), rim(h, (0.0, 1.0))], false),
                    (vec![rim(h, (1.0, 0.0)), rim(-h, (1.0, 0.0))], false),
                    (vec![rim(-h, (0.0, -1.0)), centre(-h)], false),
                ],
                &phi,
                &mut m,
                max_triangles,
            )?;
            m
        }
        Shape::Torus {
            major_radius,
            minor_radius,
        } => {
            let (big, small) = (major_radius, minor_radius);
            let v_closed = sample_span(detail, (0.0, TAU), small, 3, max_per_turn, |a, b| {
                let Detail::Screen(budget) = detail else {
                    return f64::INFINITY;
                };
                let (c_min, c_max) = cos_range(a, b);
                let (s_min, s_max) = sin_range(a, b);
                let radial = (big + small * c_min, big + small * c_max);
                step_for(
                    budget.ring_error(radial, (-small * s_max, -small * s_min)),
                    small,
                )
            });
            let bands: Vec<Band> = v_closed
                .windows(2)
                .map(|w| {
                    let (c_min, c_max) = cos_range(w[0], w[1]);
                    let (s_min, s_max) = sin_range(w[0], w[1]);
                    Band {
                        radial: (big + small * c_min, big + small * c_max),
                        y: (-small * s_max, -small * s_min),
                    }
                })
                .collect();
            let phi = revolution_angles(detail, &bands, 3, max_per_turn);
            let v = turn(v_closed);
            let profile: Vec<ProfilePoint> = v
                .iter()
                .map(|&t| {
                    let (s, c) = t.sin_cos();
                    ProfilePoint {
                        radial: big + small * c,
                        y: -small * s,
                        normal: (c, -s),
                        pole: false,
                    }
                })
                .collect();
            let mut m = LocalMesh {
                closed: true,
                segments: vec![phi.len() as u32, v.len() as u32],
                ..LocalMesh::default()
            };
            revolve(&[(profile, true)], &phi, &mut m, max_triangles)?;
            m
        }
        Shape::Capsule {
            radius,
            half_height,
        } => capsule(radius, half_height, detail, max_per_turn, max_triangles)?,
        Shape::CappedCone {
            half_height,
            bottom_radius,
            top_radius,
        } => capped_cone(
            half_height,
            bottom_radius,
            top_radius,
            detail,
            max_per_turn,
            max_triangles,
        )?,
        Shape::RoundedBox {
            half_extents,
            rounding_radius,
        } => rounded_box(
            half_extents,
            rounding_radius,
            detail,
            max_per_turn,
            max_triangles,
        )?,
        Shape::Box { half_extents } => box_mesh(half_extents),
        Shape::Triangle { vertices } => LocalMesh {
            positions: vertices.to_vec(),
            normals: None,
            triangles: vec![[0, 1, 2]],
            closed: false,
            segments: Vec::new(),
            materials: None,
        },
        Shape::Plane { .. } | Shape::Mesh { .. } => return Ok(None),
    };
    Ok(Some(mesh))
}

/// A capsule (radius `r`, segment `|y| <= h`) as a latitude-longitude sphere of radius `r`
/// whose upper half is moved up by `h` and lower half down by `h`, the equator row doubled
/// so the band between the halves is the cylinder.
fn capsule(
    r: f64,
    h: f64,
    detail: Detail,
    max_per_turn: u32,
    max_triangles: u64,
) -> Result<LocalMesh, TooManyTriangles> {
    // Every point of the rounded ends moves by at most r per radian squared.
    let theta = sample_span(detail, (0.0, FRAC_PI_2), r, 1, max_per_turn, |a, b| {
        let Detail::Screen(budget) = detail else {
            return f64::INFINITY;
        };
        let radial = mul_range((r, r), sin_range(a, b));
        let y = mul_range((r, r), cos_range(a, b));
        step_for(
            budget
                .ring_error(radial, (y.0 + h, y.1 + h))
                .min(budget.ring_error(radial, (-y.1 - h, -y.0 - h))),
            r,
        )
    });
    let bands: Vec<Band> = theta
        .windows(2)
        .map(|w| {
            let y = mul_range((r, r), cos_range(w[0], w[1]));
            Band {
                radial: mul_range((r, r), sin_range(w[0], w[1])),
                y: (-y.1 - h, y.1 + h),
            }
        })
        .collect();
    let phi = revolution_angles(detail, &bands, 3, max_per_turn);
    let point = |t: f64, shift: f64, pole: bool| {
        let (s, c) = t.sin_cos();
        let (s, c) = if pole { (0.0, c.signum()) } else { (s, c) };
        ProfilePoint {
            radial: r * s,
            y: r * c + shift,
            normal: (s, c),
            pole,
        }
    };
    let last = theta.len() - 1;
    let mut profile: Vec<ProfilePoint> = Vec::with_capacity(2 * theta.len());
    for (k, &t) in theta.iter().enumerate() {
        // The equator row exactly on the side: normal (1, 0).
        let t = if k == last { FRAC_PI_2 } else { t };
        profile.push(point(t, h, k == 0));
    }
    for (k, &t) in theta.iter().enumerate().rev() {
        let t = if k == last { FRAC_PI_2 } else { PI - t };
        profile.push(point(t, -h, k == 0));
    }
    // The equator's cosine is not exactly 0 in f64: put both rows on the side exactly.
    for p in &mut profile {
        if !p.pole && p.normal.0 == 1.0 {
            p.normal.1 = 0.0;
        }
    }
    profile[last].y = h;
    profile[last].normal = (1.0, 0.0);
    profile[last + 1].y = -h;
    profile[last + 1].normal = (1.0, 0.0);
    let mut mesh = LocalMesh {
        closed: true,
        segments: vec![phi.len() as u32, 4 * last as u32],
        ..LocalMesh::default()
    };
    revolve(&[(profile, false)], &phi, &mut mesh, max_triangles)?;
    Ok(mesh)
}

/// A capped cone (radius `r1` at `y = -h`, `r2` at `y = h`) revolved like the cylinder:
/// a cap, the slanted side and a cap; a cap of radius 0 is the apex (a pole).
fn capped_cone(
    h: f64,
    r1: f64,
    r2: f64,
    detail: Detail,
    max_per_turn: u32,
    max_triangles: u64,
) -> Result<LocalMesh, TooManyTriangles> {
    let bands = [Band {
        radial: (0.0, r1.max(r2)),
        y: (-h, h),
    }];
    let phi = revolution_angles(detail, &bands, 3, max_per_turn);
    // Outward normal of the side in the (radial, y) plane: along (2h, r1 - r2).
    let side = glam::DVec2::new(2.0 * h, r1 - r2).normalize();
    let rim = |radial: f64, y: f64, normal: (f64, f64)| ProfilePoint {
        radial,
        y,
        normal,
        pole: radial == 0.0,
    };
    let centre = |y: f64| ProfilePoint {
        radial: 0.0,
        y,
        normal: (0.0, y.signum()),
        pole: true,
    };
    let mut pieces = Vec::with_capacity(3);
    if r2 > 0.0 {
        pieces.push((vec![centre(h), rim(r2, h, (0.0, 1.0))], false));
    }
    pieces.push((
        vec![rim(r2, h, (side.x, side.y)), rim(r1, -h, (side.x, side.y))],
        false,
    ));
    if r1 > 0.0 {
        pieces.push((vec![rim(r1, -h, (0.0, -1.0)), centre(-h)], false));
    }
    let mut mesh = LocalMesh {
        closed: true,
        segments: vec![phi.len() as u32],
        ..LocalMesh::default()
    };
    revolve(&pieces, &phi, &mut mesh, max_triangles)?;
    Ok(mesh)
}

/// A rounded box (outer half extents `half`, rounding radius `r`) as a cube-sphere of
/// radius `r` cut open along the three coordinate planes, its eight octants moved out to
/// the inner box's corners `±(half - r)`: each face of the cube grid samples its angles from
/// -45 to 45 degrees per direction with the 0 row doubled (one copy per side of the cut), so
/// the band between the copies becomes the flat face or the cylindrical edge. Points and
/// normals are exact on the surface; rows shared by two faces are computed from the same
/// inputs, so the mesh is watertight. `r = 0` is the plain box.
fn rounded_box(
    half: DVec3,
    r: f64,
    detail: Detail,
    max_per_turn: u32,
    max_triangles: u64,
) -> Result<LocalMesh, TooManyTriangles> {
    if r <= 0.0 {
        return Ok(box_mesh(half));
    }
    let inner = (half - DVec3::splat(r)).max(DVec3::ZERO);
    // The curved parts are arcs of radius r; a screen budget takes the error allowed at the
    // box's nearest point (the finest the shape needs anywhere).
    let detail = match detail {
        Detail::Screen(budget) => Detail::ChordError(budget.local_error((-half, half))),
        other => other,
    };
    // Segments per 45 degrees.
    let m = segments(detail, r, 0.125, 1, max_per_turn).max(1);
    let step = FRAC_PI_4 / f64::from(m);
    // Per face direction along `axis`: (tangent of the angle, side of the cut), -45 to 45
    // degrees, the 0 row doubled where the inner box has extent along the axis. The ends
    // are exactly -1, 0 and 1 so that faces meeting at an edge compute the same points.
    let samples = |axis: usize| -> Vec<(f64, f64)> {
        let tan = |i: u32| match i {
            0 => 0.0,
            i if i == m => 1.0,
            i => (step * f64::from(i)).tan(),
        };
        let mut v: Vec<(f64, f64)> = (0..=m).rev().map(|i| (-tan(i), -1.0)).collect();
        let first_positive = if inner[axis] > 0.0 { 0 } else { 1 };
        v.extend((first_positive..=m).map(|i| (tan(i), 1.0)));
        v
    };
    // Each face as (normal axis, sign, u axis, v axis) with u x v = normal (as `box_mesh`).
    let faces = [
        (0, 1.0, 1, 2),
        (0, -1.0, 2, 1),
        (1, 1.0, 2, 0),
        (1, -1.0, 0, 2),
        (2, 1.0, 0, 1),
        (2, -1.0, 1, 0),
    ];
    let planned: u64 = faces
        .iter()
        .map(|&(_, _, u, v)| 2 * (samples(u).len() as u64 - 1) * (samples(v).len() as u64 - 1))
        .sum();
    if planned > max_triangles {
        return Err(TooManyTriangles {
            triangles: planned,
            segments: vec![8 * m],
        });
    }
    let mut mesh = LocalMesh {
        closed: true,
        segments: vec![8 * m],
        normals: Some(Vec::new()),
        ..LocalMesh::default()
    };
    for (axis, sign, u, v) in faces {
        let (su, sv) = (samples(u), samples(v));
        let start = mesh.positions.len() as u32;
        for &(tv, side_v) in &sv {
            for &(tu, side_u) in &su {
                let mut c = DVec3::ZERO;
                c[axis] = sign;
                c[u] = tu;
                c[v] = tv;
                let n = c.normalize();
                let mut side = DVec3::ZERO;
                side[axis] = sign;
                side[u] = side_u;
                side[v] = side_v;
                mesh.positions.push(side * inner + r * n);
                if let Some(normals) = &mut mesh.normals {
                    normals.push(n);
                }
            }
        }
        let row = su.len() as u32;
        for j in 0..sv.len() as u32 - 1 {
            for i in 0..row - 1 {
                let a = start + j * row + i;
                let (b, c, d) = (a + 1, a + row + 1, a + row);
                mesh.triangles.push([a, b, c]);
                mesh.triangles.push([a, c, d]);
            }
        }
    }
    Ok(mesh)
}

/// The 12 triangles of an axis-aligned box (exact; flat faces, no vertex normals).
fn box_mesh(half: DVec3) -> LocalMesh {
    let corner =
        |sx: bool, sy: bool, sz: bool| u32::from(sx) | (u32::from(sy) << 1) | (u32::from(sz) << 2);
    let positions = (0..8u32)
        .map(|i| {
            DVec3::new(
                if i & 1 != 0 { half.x } else { -half.x },
                if i & 2 != 0 { half.y } else { -half.y },
                if i & 4 != 0 { half.z } else { -half.z },
            )
        })
        .collect();
    // Each face as (normal axis, sign, u axis, v axis) with u x v = normal.
    let faces = [
        (0, true, 1, 2),
        (0, false, 2, 1),
        (1, true, 2, 0),
        (1, false, 0, 2),
        (2, true, 0, 1),
        (2, false, 1, 0),
    ];
    let mut triangles = Vec::with_capacity(12);
    for (axis, positive, u, v) in faces {
        let at = |su: bool, sv: bool| {
            let mut s = [false; 3];
            s[axis] = positive;
            s[u] = su;
            s[v] = sv;
            corner(s[0], s[1], s[2])
        };
        let (a, b, c, d) = (
            at(false, false),
            at(true, false),
            at(true, true),
            at(false, true),
        );
        triangles.push([a, b, c]);
        triangles.push([a, c, d]);
    }
    LocalMesh {
        positions,
        normals: None,
        triangles,
        closed: true,
        segments: Vec::new(),
        materials: None,
    }
}
