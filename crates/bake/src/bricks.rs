//! Baking the sparse narrow-band brick grid ([`SparseGrid`]): only the band is computed.
//!
//! Phases (each timed in [`SparseBakeStats`]):
//!
//! 1. **Coarse**: the exact distance `d_c` at every brick cell's centre (branch-and-bound
//!    over the BVH, in parallel). A brick cell whose `d_c` exceeds the reach of its box
//!    (half its diagonal, `4 sqrt(3)` cells) plus the band cannot hold a band sample: it
//!    stays empty and keeps `d_c` as its distance bound. No sample of empty space is ever
//!    computed.
//! 2. **Distance**: for the remaining candidates, the exact distance of every brick sample
//!    (the `(BRICK + 1)^3` lattice samples), with the dense bake's candidate list: the triangles within `d_c +
//!    2 r` of the centre sorted by distance, each sample stopping at the first that cannot
//!    beat its best. A candidate whose core samples are all farther than the band plus half
//!    a cell diagonal holds no surface within the band: it is dropped (empty).
//! 3. **Sign**: when the faces are consistently oriented ([`consistently_oriented`]; closed
//!    or not: the open teapot's patches and the dragon scan are), a sample whose closest
//!    point lies inside a face (not on an edge or vertex) takes the side of that face's
//!    plane (the face case of Baerentzen & Aanaes 2005, "Signed distance computation using
//!    the angle weighted pseudonormal"); signs then spread to neighbouring samples wherever
//!    no surface can lie between the two (`|d_a| + |d_b| > h`: their empty balls cover the
//!    segment); a sample still unknown evaluates the fast generalized winding number
//!    (Jacobson et al. 2013; Barill et al. 2018), inside at `w >= 0.5`, and spreads it. A
//!    brick where two neighbours' signs differ although no surface can lie between them
//!    (open sheets' rims, interpenetrating parts) takes every sample's side from the winding
//!    number instead, as the dense grid does. Empty brick cells take the winding number's
//!    side at their centre: across a large hole the boundary between inside and outside
//!    empty cells is still a cap (the dense grid's limitation).
//! 4. **Encode**: clamp to `band + 1` cells ([`CLAMP_BEYOND_BAND`]) and quantize
//!    ([`Quantization`]).
//!
//! Everything runs on the caller's rayon pool.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use glam::Vec3;
use marchmesh_meshio::TriangleMesh;
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::sparse::{
    BOUND_MAX, BOUND_STEPS, BRICK, EMPTY, INSIDE, Quantization, Reconstruction, Samples,
    SparseGrid, encode_octahedral,
};
use crate::{
    BakeError, CANDIDATES_PER_SAMPLE, MAX_RESOLUTION, MIN_RESOLUTION, PAD_CELLS, cache,
    point_triangle_distance_squared, triangles_of,
};

/// Cells beyond the band to which stored distances are clamped (`clamp = (band + this) *
/// cell`): the quantization step is `2 clamp / 255` for u8.
pub const CLAMP_BEYOND_BAND: u32 = 1;

/// Smallest accepted [`SparseOptions::band_voxels`].
pub const MIN_BAND_VOXELS: u32 = 1;
/// Largest accepted [`SparseOptions::band_voxels`] (a wider band is a dense grid).
pub const MAX_BAND_VOXELS: u32 = 16;

/// How to bake a sparse grid.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SparseOptions {
    /// Cells along the longest side of the mesh bounds (the effective resolution), in
    /// `MIN_RESOLUTION..=MAX_RESOLUTION`. Memory and bake time scale with `resolution^2`
    /// (the surface), not `^3`.
    pub resolution: u32,
    /// Band half-width in cells, `MIN_BAND_VOXELS..=MAX_BAND_VOXELS` (default 2): brick
    /// cells the surface comes within this many cells of hold bricks; elsewhere the field is
    /// at least this distance. Wider: more bricks, larger steps near the surface.
    pub band_voxels: u32,
    /// Sample storage (default [`Quantization::F32`]).
    pub quantization: Quantization,
    /// Interpolation (default [`Reconstruction::Trilinear`]).
    pub reconstruction: Reconstruction,
    /// Directory for cached grids (created if missing); `None` = no cache.
    pub cache_dir: Option<PathBuf>,
}

impl SparseOptions {
    /// The defaults: resolution 256, band 2 cells, f32, trilinear, no cache.
    pub const DEFAULT: SparseOptions = SparseOptions {
        resolution: 256,
        band_voxels: 2,
        quantization: Quantization::F32,
        reconstruction: Reconstruction::Trilinear,
        cache_dir: None,
    };

    /// Checks the ranges (resolution, band).
    pub fn validate(&self) -> Result<(), BakeError> {
        if !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&self.resolution) {
            return Err(BakeError::Resolution {
                resolution: self.resolution,
            });
        }
        if !(MIN_BAND_VOXELS..=MAX_BAND_VOXELS).contains(&self.band_voxels) {
            return Err(BakeError::Band {
                band_voxels: self.band_voxels,
            });
        }
        Ok(())
    }

    /// Upper bound of the bytes a sparse grid baked with these options can hold for a mesh
    /// whose bounds' longest side has `resolution` cells, whatever the mesh: every brick
    /// cell of the (at most cubic) lattice holding a brick, plus the brick-cell words. The
    /// real figure is proportional to the surface (about 1 MB for the bunny at 256 in u8).
    pub fn max_grid_bytes(&self) -> u64 {
        let cells = u64::from(self.resolution) + 2 * u64::from(PAD_CELLS) + 1;
        let per_axis = cells.div_ceil(u64::from(BRICK));
        let brick_cells = per_axis.pow(3);
        let edge = u64::from(BRICK + 1 + 2 * self.reconstruction.apron());
        let normal_bytes = match self.reconstruction {
            Reconstruction::Normals => 2,
            _ => 0,
        };
        brick_cells
            .saturating_mul(edge.pow(3) * (self.quantization.bytes() as u64 + normal_bytes) + 4)
            .saturating_add(std::mem::size_of::<SparseGrid>() as u64)
    }
}

impl SparseOptions {
    /// Upper bound of the bytes a bake with these options holds at its peak: the grid
    /// ([`SparseOptions::max_grid_bytes`]) plus every brick's unquantized f32 samples, which
    /// are kept until they are encoded (the BVH is the caller's to count: it scales with
    /// the triangles).
    pub fn max_bake_bytes(&self) -> u64 {
        let cells = u64::from(self.resolution) + 2 * u64::from(PAD_CELLS) + 1;
        let brick_cells = cells.div_ceil(u64::from(BRICK)).pow(3);
        let edge = u64::from(BRICK + 1 + 2 * self.reconstruction.apron());
        self.max_grid_bytes()
            .saturating_add(brick_cells.saturating_mul(edge.pow(3) * 4 + 16))
    }
}

impl Default for SparseOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A baked sparse grid and how it was obtained.
pub type BakedSparse = crate::Baked<SparseGrid>;

/// Work counters, times and bytes of a sparse bake (zero when read from the cache).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SparseBakeStats {
    /// Brick cells of the lattice.
    pub brick_cells: u64,
    /// Brick cells whose centre was near enough to the surface to compute their samples.
    pub candidates: u64,
    /// Bricks kept (surface within the band).
    pub bricks: u64,
    /// Bricks whose face sides contradicted their distances, re-signed sample by sample
    /// with the winding number.
    pub winding_bricks: u64,
    /// Distances computed (brick centres plus candidate samples).
    pub distance_evaluations: u64,
    /// Winding numbers evaluated (the other samples took a face's side).
    pub winding_evaluations: u64,
    /// Wall time of the BVH build, ms.
    pub bvh_ms: f64,
    /// Wall time of the coarse pass (brick-centre distances), ms.
    pub coarse_ms: f64,
    /// Wall time of the band distances, ms.
    pub distance_ms: f64,
    /// Wall time of the signs (face sides, winding numbers, cap detection), ms.
    pub sign_ms: f64,
    /// Wall time of clamping, quantizing and assembling, ms.
    pub encode_ms: f64,
    /// Bytes of the bake's BVH (freed afterwards).
    pub bvh_bytes: u64,
    /// Bytes of the coarse pass's working data (one distance and flag per brick cell).
    pub coarse_bytes: u64,
    /// Peak bytes of unquantized candidate samples (f32 distances and signs).
    pub band_bytes: u64,
    /// Bytes of the finished grid.
    pub grid_bytes: u64,
}

/// Bakes `mesh` (its own coordinates) into a sparse narrow-band grid, or loads it from
/// `opts.cache_dir`. Errors: [`BakeError::Resolution`], [`BakeError::Band`],
/// [`BakeError::Empty`], [`BakeError::InvalidMesh`]; cache problems only add notes.
pub fn bake_sparse(
    mesh: &TriangleMesh,
    opts: &SparseOptions,
) -> Result<(BakedSparse, SparseBakeStats), BakeError> {
    let t0 = Instant::now();
    opts.validate()?;
    let path = mesh.report.source.clone();
    let tris = triangles_of(mesh)?;
    let hash = mesh.content_hash();
    crate::bake_or_load(
        t0,
        opts.cache_dir
            .as_ref()
            .map(|d| cache::sparse_cache_path(d, hash, opts)),
        "sparse grid",
        |b| cache::decode_sparse(b, hash, opts),
        |grid| format!("sparse grid ({} bricks)", grid.brick_count()),
        |notes| {
            let closed = mesh.is_closed();
            let oriented = consistently_oriented(mesh);
            let (grid, stats) = bake_bricks(tris, opts, oriented, &path)?;
            let s = &stats;
            notes.push(format!(
                "baked {} triangles into a sparse grid at {} cells on the longest side (cell {:.4e}): {} of {} brick cells hold {}^3-cell bricks ({} candidates, {} signed by winding numbers), {} {} samples, band {} cells, clamp {:.3e}, {}; {} B; {:.1} ms (bvh {:.1}, coarse {:.1}, distance {:.1}, sign {:.1}, encode {:.1}); {} distances, {} winding numbers",
                mesh.triangles.len(),
                opts.resolution,
                grid.cell_size(),
                s.bricks,
                s.brick_cells,
                BRICK,
                s.candidates,
                s.winding_bricks,
                grid.samples().len(),
                opts.quantization.name(),
                opts.band_voxels,
                grid.clamp(),
                opts.reconstruction.name(),
                grid.memory_bytes(),
                t0.elapsed().as_secs_f64() * 1e3,
                s.bvh_ms,
                s.coarse_ms,
                s.distance_ms,
                s.sign_ms,
                s.encode_ms,
                s.distance_evaluations,
                s.winding_evaluations,
            ));
            if !closed {
                notes.push(format!(
                    "mesh {} is not closed: signs from face sides{} and the winding number; {} brick(s) whose face sides contradict their distances are signed by the winding number sample by sample; large holes may still get a cap (as in the dense grid)",
                    path.display(),
                    if oriented { "" } else { " (not used: faces inconsistently oriented)" },
                    s.winding_bricks
                ));
            }
            Ok((grid, stats))
        },
        |grid| cache::encode_sparse(grid, hash, opts),
    )
}

/// Lattice for the mesh bounds `(lo, hi)` at `res` cells on the longest side, padded by
/// [`PAD_CELLS`] and rounded up to whole bricks, centred on the mesh: `(min, cell, bricks)`.
pub(crate) fn sparse_lattice(lo: Vec3, hi: Vec3, res: u32) -> Option<(Vec3, f32, [u32; 3])> {
    let ext = hi - lo;
    let longest = ext.max_element();
    if longest.is_nan() || longest <= 0.0 || !longest.is_finite() {
        return None;
    }
    let h = longest / res as f32;
    let cells = (ext / h - Vec3::splat(1e-3))
        .ceil()
        .max(Vec3::ONE)
        .as_uvec3()
        + glam::UVec3::splat(2 * PAD_CELLS);
    let bricks = (cells + glam::UVec3::splat(BRICK - 1)) / BRICK;
    let total = (bricks * BRICK).as_vec3();
    let min = 0.5 * (lo + hi) - 0.5 * h * total;
    Some((min, h, bricks.to_array()))
}

/// The side of `tri`'s plane `p` is on when its closest point on `tri` lies strictly inside
/// the face (`Some(true)` = behind the counter-clockwise normal, inside); `None` when it lies
/// on an edge or vertex (or the triangle is degenerate), where only the winding number
/// decides.
#[inline]
fn face_side(p: Vec3, t: &[Vec3; 3]) -> Option<bool> {
    let (ab, ac) = (t[1] - t[0], t[2] - t[0]);
    let n = ab.cross(ac);
    let n2 = n.length_squared();
    if n2.is_nan() || n2 <= 1e-6 * ab.length_squared() * ac.length_squared() {
        return None;
    }
    let ap = p - t[0];
    let off = n.dot(ap) / n2;
    let q = ap - n * off;
    // Barycentrics of the projection q (relative to a).
    let (d00, d01, d11) = (ab.dot(ab), ab.dot(ac), ac.dot(ac));
    let (d20, d21) = (q.dot(ab), q.dot(ac));
    let den = d00 * d11 - d01 * d01;
    if den.is_nan() || den <= 0.0 {
        return None;
    }
    let v = (d11 * d20 - d01 * d21) / den;
    let w = (d00 * d21 - d01 * d20) / den;
    let u = 1.0 - v - w;
    const MARGIN: f32 = 1e-3;
    if u > MARGIN && v > MARGIN && w > MARGIN && off != 0.0 {
        Some(off < 0.0)
    } else {
        None
    }
}

/// True when every edge shared by two or more triangles (vertices welded by position) is
/// walked as often in one direction as in the other: the faces agree on their orientation,
/// open or not (the teapot's unwelded patches, the dragon scan's non-manifold pinches), so
/// the side of a face's plane is the side of the solid next to that face. Triangles with
/// out-of-range indices make it false.
pub(crate) fn consistently_oriented(mesh: &TriangleMesh) -> bool {
    mesh.edge_uses().is_some_and(|edges| {
        edges
            .iter()
            .all(|(&(a, b), e)| a == b || e.uses < 2 || e.net == 0)
    })
}

/// True when two neighbouring samples of a brick (`edge`^3, x fastest) have opposite signs
/// although their distances add up to more than `lim` (their spacing): no surface can lie
/// between them, so one sign is wrong (a winding-number cap across a hole).
fn has_cap(values: &[f32], edge: usize, lim: f32) -> bool {
    for k in 0..edge {
        for j in 0..edge {
            for i in 0..edge {
                let idx = i + edge * (j + edge * k);
                let v = values[idx];
                for (ok, step) in [
                    (i + 1 < edge, 1),
                    (j + 1 < edge, edge),
                    (k + 1 < edge, edge * edge),
                ] {
                    if ok {
                        let w = values[idx + step];
                        if (v < 0.0) != (w < 0.0) && v.abs() + w.abs() > lim {
                            return true;
                        }
                    }
                }
            }
        }
    }
    false
}

/// One kept brick's signed samples.
struct BrickOut {
    values: Vec<f32>,
    /// Octahedral normal codes ([`Reconstruction::Normals`] only, else empty).
    normals: Vec<u16>,
    rewound: bool,
    windings: u64,
}

/// The signed samples of candidate brick cell `b`, or `None` when no core
/// sample is within the band plus half a cell diagonal. Adds its distance and sign times to
/// `ns` (nanoseconds).
#[allow(clippy::too_many_arguments)]
fn brick_samples(
    bvh: &Bvh,
    min: Vec3,
    h: f32,
    b: [u32; 3],
    edge: usize,
    apron: u32,
    band_voxels: u32,
    clamp: f32,
    oriented: bool,
    with_normals: bool,
    cand: &mut Vec<(f32, u32)>,
    ns: &[AtomicU64; 2],
) -> Option<BrickOut> {
    let t_dist = Instant::now();
    let o = [0, 1, 2].map(|a| (BRICK * b[a]) as f32 - apron as f32);
    let at = |i: usize, j: usize, k: usize| {
        min + h * Vec3::new(o[0] + i as f32, o[1] + j as f32, o[2] + k as f32)
    };
    let n = edge * edge * edge;
    let mut dist = vec![0.0f32; n];
    let mut closest = vec![u32::MAX; n];
    // Sub-blocks of SUB^3 samples, as the dense bake's blocks: the sub-block centre's exact
    // distance bounds its samples', so the candidates are the triangles within `dc + 2 r`.
    const SUB: usize = 3;
    let mut hint = u32::MAX;
    for k0 in (0..edge).step_by(SUB) {
        let kn = SUB.min(edge - k0);
        for j0 in (0..edge).step_by(SUB) {
            let jn = SUB.min(edge - j0);
            for i0 in (0..edge).step_by(SUB) {
                let in_ = SUB.min(edge - i0);
                let span = Vec3::new((in_ - 1) as f32, (jn - 1) as f32, (kn - 1) as f32);
                let c = at(i0, j0, k0) + 0.5 * h * span;
                let r = 0.5 * h * span.length();
                let (dc2, t) = bvh.closest(c, hint);
                hint = t;
                let dc = dc2.sqrt();
                if dc - r >= clamp * (1.0 + 1e-4) {
                    // Every sample of the sub-block is beyond the clamp: its stored value is
                    // the clamp whatever the exact distance (about 2/3 of a brick's samples),
                    // and its side comes from its neighbours (or the winding number).
                    for k in k0..k0 + kn {
                        for j in j0..j0 + jn {
                            for i in i0..i0 + in_ {
                                dist[i + edge * (j + edge * k)] = clamp;
                            }
                        }
                    }
                    continue;
                }
                // Triangles farther than `clamp + r` from the centre cannot bring a sample
                // below the clamp, so the candidates stop there too.
                let reach = ((dc + 2.0 * r).min(clamp + r) * (1.0 + 1e-5)) + 1e-6 * h;
                let exhaustive = !bvh.gather(c, reach, CANDIDATES_PER_SAMPLE * in_ * jn * kn, cand);
                if !exhaustive {
                    cand.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
                }
                for k in k0..k0 + kn {
                    for j in j0..j0 + jn {
                        for i in i0..i0 + in_ {
                            let p = at(i, j, k);
                            let idx = i + edge * (j + edge * k);
                            if exhaustive {
                                let (d2, tt) = bvh.closest(p, hint);
                                dist[idx] = d2.sqrt();
                                closest[idx] = tt;
                                continue;
                            }
                            let s = (p - c).length();
                            // Start at the clamp: a sample no triangle brings below it is
                            // stored as the clamp, side unknown (`u32::MAX`).
                            let (mut best2, mut best, mut bt) = (clamp * clamp, clamp, u32::MAX);
                            for &(tc, ti) in cand.iter() {
                                if tc - s >= best {
                                    break;
                                }
                                let tr = bvh.tri(ti);
                                let d2 = point_triangle_distance_squared(p, tr[0], tr[1], tr[2]);
                                if d2 < best2 {
                                    (best2, best, bt) = (d2, d2.sqrt(), ti);
                                }
                            }
                            dist[idx] = best;
                            closest[idx] = bt;
                        }
                    }
                }
            }
        }
    }
    // Keep only bricks with a core sample within the band plus half a cell diagonal: then
    // every point of a dropped brick's box is farther than the band from the surface.
    let a = apron as usize;
    let keep_below = (band_voxels as f32 + 0.5 * 3f32.sqrt()) * h * (1.0 + 1e-4);
    let mut near = false;
    'scan: for k in a..=a + BRICK as usize {
        for j in a..=a + BRICK as usize {
            for i in a..=a + BRICK as usize {
                if dist[i + edge * (j + edge * k)] <= keep_below {
                    near = true;
                    break 'scan;
                }
            }
        }
    }
    ns[0].fetch_add(t_dist.elapsed().as_nanos() as u64, Ordering::Relaxed);
    if !near {
        return None;
    }
    let t_sign = Instant::now();
    // Signs: the face's side where the closest point is inside a face; then propagated to
    // neighbours where no surface can lie between the two samples (either one's distance
    // exceeds the spacing, so its empty ball covers the segment); the winding number only
    // seeds what is left.
    let mut windings = 0u64;
    let mut side: Vec<Option<bool>> = (0..n)
        .map(|idx| {
            let (i, j, k) = (idx % edge, (idx / edge) % edge, idx / (edge * edge));
            let t = closest[idx];
            if t == u32::MAX || !oriented {
                None
            } else {
                face_side(at(i, j, k), bvh.tri(t))
            }
        })
        .collect();
    let link = h * (1.0 + 1e-3) + 1e-6 * h;
    let mut queue: Vec<usize> = (0..n).filter(|&i| side[i].is_some()).collect();
    let mut next_unknown = 0usize;
    loop {
        while let Some(a) = queue.pop() {
            let sa = side[a];
            let (i, j, k) = (a % edge, (a / edge) % edge, a / (edge * edge));
            let nbrs = [
                (i > 0).then(|| a - 1),
                (i + 1 < edge).then(|| a + 1),
                (j > 0).then(|| a - edge),
                (j + 1 < edge).then(|| a + edge),
                (k > 0).then(|| a - edge * edge),
                (k + 1 < edge).then(|| a + edge * edge),
            ];
            for b in nbrs.into_iter().flatten() {
                // The two empty balls cover the segment: no surface between a and b.
                if side[b].is_none() && dist[a] + dist[b] > link {
                    side[b] = sa;
                    queue.push(b);
                }
            }
        }
        while next_unknown < n && side[next_unknown].is_some() {
            next_unknown += 1;
        }
        if next_unknown == n {
            break;
        }
        let (i, j, k) = (
            next_unknown % edge,
            (next_unknown / edge) % edge,
            next_unknown / (edge * edge),
        );
        windings += 1;
        side[next_unknown] = Some(bvh.winding(at(i, j, k)) >= 0.5);
        queue.push(next_unknown);
    }
    let values: Vec<f32> = dist
        .iter()
        .zip(&side)
        .map(|(&d, s)| if *s == Some(true) { -d } else { d })
        .collect();
    // A sign change between neighbours with no room for a surface between them is a cap.
    let mut values = values;
    let lim = h * (1.0 + 1e-3) + 1e-6 * h;
    let rewound = has_cap(&values, edge, lim);
    if rewound {
        // The face sides and their spreading contradict the distances here (an open
        // sheet's rim, interpenetrating parts such as the teapot's spout in its body): every
        // sample takes the winding number's side instead, as the dense grid does. A cap
        // across a hole may remain (the dense grid's limitation); storing such bricks
        // unsigned (`|d| - h/2`) was measured worse: trilinear interpolation of `|d|`
        // ripples by up to half a cell, and it broke the teapot (10.6 deg mean normal error
        // at 128 against 3.2 with the winding number's sides).
        for (idx, v) in values.iter_mut().enumerate() {
            let (i, j, k) = (idx % edge, (idx / edge) % edge, idx / (edge * edge));
            windings += 1;
            let d = v.abs();
            *v = if bvh.winding(at(i, j, k)) >= 0.5 {
                -d
            } else {
                d
            };
        }
    }
    let normals = if with_normals {
        (0..n)
            .map(|idx| {
                let (i, j, k) = (idx % edge, (idx / edge) % edge, idx / (edge * edge));
                encode_octahedral(sample_normal(
                    at(i, j, k),
                    values[idx],
                    closest[idx],
                    bvh,
                    || brick_gradient(&values, edge, [i, j, k]),
                ))
            })
            .collect()
    } else {
        Vec::new()
    };
    ns[1].fetch_add(t_sign.elapsed().as_nanos() as u64, Ordering::Relaxed);
    Some(BrickOut {
        normals,
        values,
        rewound,
        windings,
    })
}

/// The normal stored with a sample at `p` of signed value `v` whose closest triangle is
/// `closest` (`u32::MAX`: none within the clamp): that triangle's unit face normal,
/// turned to point the way the signed distance grows (towards `p` when `p` is outside
/// the face's plane and `v > 0`, and so on); `fallback` (the samples' own gradient) when
/// there is no triangle, it is degenerate, or `p` lies in its plane with no side to check.
fn sample_normal(
    p: Vec3,
    v: f32,
    closest: u32,
    bvh: &Bvh,
    fallback: impl FnOnce() -> Vec3,
) -> Vec3 {
    if closest == u32::MAX {
        return fallback();
    }
    let t = bvh.tri(closest);
    let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
    if n == Vec3::ZERO {
        return fallback();
    }
    let side = n.dot(p - t[0]);
    let scale = (t[1] - t[0]).length().max((t[2] - t[0]).length());
    if side.abs() <= 1e-4 * scale {
        // In the face's plane: oriented faces point outward, which is the growing side.
        return n;
    }
    if (side > 0.0) == (v > 0.0) { n } else { -n }
}

/// Central differences of a brick's samples at local `(i, j, k)` (one-sided on its faces).
fn brick_gradient(values: &[f32], edge: usize, ijk: [usize; 3]) -> Vec3 {
    let at = |q: [usize; 3]| values[q[0] + edge * (q[1] + edge * q[2])];
    let mut g = [0.0f32; 3];
    for (a, ga) in g.iter_mut().enumerate() {
        let (mut lo, mut hi) = (ijk, ijk);
        lo[a] = ijk[a].saturating_sub(1);
        hi[a] = (ijk[a] + 1).min(edge - 1);
        let span = (hi[a] - lo[a]).max(1) as f32;
        *ga = (at(hi) - at(lo)) / span;
    }
    Vec3::from_array(g)
}

fn bake_bricks(
    tris: Vec<[Vec3; 3]>,
    opts: &SparseOptions,
    oriented: bool,
    path: &Path,
) -> Result<(SparseGrid, SparseBakeStats), BakeError> {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for t in &tris {
        for v in t {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    let (min, h, bricks) =
        sparse_lattice(lo, hi, opts.resolution).ok_or_else(|| BakeError::InvalidMesh {
            path: path.to_path_buf(),
            reason: format!("bounds {lo}..{hi} have no extent"),
        })?;
    let mut stats = SparseBakeStats::default();
    let t = Instant::now();
    let bvh = Bvh::build(tris);
    stats.bvh_ms = t.elapsed().as_secs_f64() * 1e3;
    stats.bvh_bytes = bvh.memory_bytes();

    // Phase 1: brick-centre distances.
    let t = Instant::now();
    let [bx, by, bz] = bricks.map(|b| b as usize);
    let n_cells = bx * by * bz;
    let band = opts.band_voxels as f32 * h;
    let core_reach = 0.5 * BRICK as f32 * h * 3f32.sqrt();
    let centre = |n: usize| {
        let b = [n % bx, (n / bx) % by, n / (bx * by)];
        min + h * (BRICK as f32) * (Vec3::new(b[0] as f32, b[1] as f32, b[2] as f32) + 0.5)
    };
    let centre_d: Vec<f32> = (0..n_cells)
        .into_par_iter()
        .map(|n| bvh.closest(centre(n), u32::MAX).0.sqrt())
        .collect();
    let candidates: Vec<usize> = (0..n_cells)
        .filter(|&n| centre_d[n] <= (core_reach + band) * (1.0 + 1e-5) + 1e-6 * h)
        .collect();
    stats.coarse_ms = t.elapsed().as_secs_f64() * 1e3;
    stats.brick_cells = n_cells as u64;
    stats.candidates = candidates.len() as u64;
    stats.coarse_bytes = (n_cells * 4 + candidates.len() * 8) as u64;

    // One cell beyond the band: the samples that set a hit and its normal (the corners of
    // the cells around the surface, within sqrt(3) cells of it) keep their values, and u8
    // codes are 5/3 finer than with the former `band + 3` (bunny 256 u8: 38.75 against 38.46
    // dB, the f32 grid's 38.77; 1% more steps). Values farther out only size steps.
    let clamp = (opts.band_voxels + CLAMP_BEYOND_BAND) as f32 * h;
    // Phases 2 and 3: candidate bricks' samples, then signs (timed together per brick and
    // split by the measured share below).
    let t = Instant::now();
    let apron = opts.reconstruction.apron();
    let edge = (BRICK + 1 + 2 * apron) as usize;
    let per = edge * edge * edge;
    let ns = [AtomicU64::new(0), AtomicU64::new(0)];
    let outs: Vec<Option<BrickOut>> = candidates
        .par_iter()
        .map_init(Vec::new, |cand, &n| {
            let b = [
                (n % bx) as u32,
                ((n / bx) % by) as u32,
                (n / (bx * by)) as u32,
            ];
            brick_samples(
                &bvh,
                min,
                h,
                b,
                edge,
                apron,
                opts.band_voxels,
                clamp,
                oriented,
                opts.reconstruction == Reconstruction::Normals,
                cand,
                &ns,
            )
        })
        .collect();
    // Wall time split between the two phases by their shares of the summed thread time.
    let band_ms = t.elapsed().as_secs_f64() * 1e3;
    let [dn, sn] = ns.map(|a| a.into_inner() as f64);
    let sign_share = if dn + sn > 0.0 { sn / (dn + sn) } else { 0.0 };
    stats.distance_ms = band_ms * (1.0 - sign_share);
    stats.sign_ms = band_ms * sign_share;
    stats.distance_evaluations = (n_cells + candidates.len() * per) as u64;
    stats.band_bytes = (outs.iter().flatten().count() * per * 4) as u64;

    // Sides of empty brick cells: the winding number at the centre, as the dense bake (for
    // open meshes this keeps its caps far from the surface; making them all outside was
    // measured worse: signed band bricks then meet outside empty cells inside the solid).
    let t = Instant::now();
    let empty_inside: Vec<bool> = {
        let is_cand: std::collections::HashSet<usize> = candidates
            .iter()
            .zip(&outs)
            .filter(|(_, o)| o.is_some())
            .map(|(&n, _)| n)
            .collect();
        (0..n_cells)
            .into_par_iter()
            .map(|n| !is_cand.contains(&n) && bvh.winding(centre(n)) >= 0.5)
            .collect()
    };
    stats.sign_ms += t.elapsed().as_secs_f64() * 1e3;
    stats.winding_evaluations =
        outs.iter().flatten().map(|o| o.windings).sum::<u64>() + n_cells as u64;

    // Phase 4: encode.
    let t = Instant::now();
    let mut cells = vec![0u32; n_cells];
    for n in 0..n_cells {
        let bound = (centre_d[n] / h * BOUND_STEPS as f32 * (1.0 - 1e-5)).floor();
        let bound = if bound.is_finite() && bound > 0.0 {
            (bound as u64).min(BOUND_MAX as u64) as u32
        } else {
            0
        };
        cells[n] = EMPTY | bound | if empty_inside[n] { INSIDE } else { 0 };
    }
    let kept: Vec<(usize, &BrickOut)> = candidates
        .iter()
        .zip(&outs)
        .filter_map(|(&n, o)| o.as_ref().map(|o| (n, o)))
        .collect();
    for (k, (n, _)) in kept.iter().enumerate() {
        cells[*n] = k as u32;
    }
    stats.bricks = kept.len() as u64;
    stats.winding_bricks = kept.iter().filter(|(_, o)| o.rewound).count() as u64;
    let q = opts.quantization;
    let m = q.max_code() as f32;
    let encode = |v: f32| ((v.clamp(-clamp, clamp) + clamp) / (2.0 * clamp) * m).round();
    let samples = match q {
        Quantization::F32 => Samples::F32(
            kept.iter()
                .flat_map(|(_, o)| o.values.iter().map(|v| v.clamp(-clamp, clamp)))
                .collect(),
        ),
        Quantization::U16 => Samples::U16(
            kept.iter()
                .flat_map(|(_, o)| o.values.iter().map(|&v| encode(v) as u16))
                .collect(),
        ),
        Quantization::U8 => Samples::U8(
            kept.iter()
                .flat_map(|(_, o)| o.values.iter().map(|&v| encode(v) as u8))
                .collect(),
        ),
    };
    let normals: Vec<u16> = kept
        .iter()
        .flat_map(|(_, o)| o.normals.iter().copied())
        .collect();
    drop(kept);
    drop(outs);
    let grid = SparseGrid::from_parts(
        min,
        h,
        bricks,
        opts.band_voxels,
        clamp,
        opts.reconstruction,
        cells,
        samples,
        normals,
    )
    .map_err(|reason| BakeError::InvalidMesh {
        path: path.to_path_buf(),
        reason: format!("sparse grid assembly failed: {reason}"),
    })?;
    stats.encode_ms = t.elapsed().as_secs_f64() * 1e3;
    stats.grid_bytes = grid.memory_bytes();
    Ok((grid, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn face_side_inside_faces_only() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y]; // normal +z
        assert_eq!(face_side(Vec3::new(0.2, 0.2, 1.0), &t), Some(false));
        assert_eq!(face_side(Vec3::new(0.2, 0.2, -1.0), &t), Some(true));
        assert_eq!(face_side(Vec3::new(2.0, 2.0, 1.0), &t), None);
        assert_eq!(face_side(Vec3::new(0.0, 0.0, 1.0), &t), None);
        assert_eq!(face_side(Vec3::new(0.2, 0.2, 0.0), &t), None);
        assert_eq!(face_side(Vec3::ONE, &[Vec3::ZERO, Vec3::X, Vec3::X]), None);
    }

    #[test]
    fn lattice_is_whole_bricks_around_the_mesh() {
        let (min, h, b) = sparse_lattice(Vec3::ZERO, Vec3::new(2.0, 1.0, 0.5), 64).unwrap();
        assert!((h - 2.0 / 64.0).abs() < 1e-7);
        assert_eq!(b, [9, 5, 3]); // 70, 38, 22 cells -> 72, 40, 24
        assert!(min.x < -(PAD_CELLS as f32) * h + 1e-6);
        assert!(sparse_lattice(Vec3::ZERO, Vec3::ZERO, 64).is_none());
        assert!(sparse_lattice(Vec3::ZERO, Vec3::splat(f32::NAN), 64).is_none());
    }
}
