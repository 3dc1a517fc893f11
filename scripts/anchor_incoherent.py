#!/usr/bin/env python3
"""Incoherent rays for the Embree anchor (issue 42): seeded ambient-occlusion and diffuse
bounce rays from the primary hits of the anchor's camera rays, as a lighting workload traces
them. Needs numpy only (scripts/anchor_embree.py uses it; scripts/test_anchor_incoherent.py
tests it).

Each hit of a camera ray (its distance and triangle, from Embree) becomes a surface point:
p = o + t d computed in f64, the triangle's geometric normal (f64 cross product of its f32
edges, turned to face the camera ray), and a ray origin offset along that normal by
`offset * max(|p|, 1e-30)`, the integrator's rule for secondary rays (`ray_offset`, 1e-4 by
default; render space puts the camera at the origin, so |p| is the distance from it). From
each point, `per_hit` rays of each kind leave in cosine-weighted directions about the normal
(Malley's method: a uniform point on the unit disk lifted onto the hemisphere):

- "ao": ambient-occlusion rays, occlusion queries with a finite tmax (`ao_distance`);
- "bounce": diffuse bounce rays, closest-hit queries with tmax = +inf;
- "shadow" (when a rectangular area light is given): one shadow ray per hit towards a uniform
  point on the light, an occlusion query ending `offset * max(|p|, 1e-30)` short of it, as the
  integrators trace area-light shadows (direction and distance from the hit point p; no ray
  where the light lies behind the surface, so there are fewer shadow rays than hits).

`boxed_obj` writes a mesh inside an open box (a Cornell-box-like room: floor, ceiling, back and
side walls, the front open towards the anchor's camera), where bounce rays meet surroundings
instead of leaving a lone mesh.

The rays keep the order of the pixels they come from (row-major), as a renderer's wavefront
of one tile's hits would: neighbouring rays start close together and leave in unrelated
directions. The same seed gives the same rays bit for bit (numpy's PCG64). Every ray is 7
float32 values: origin (3), unit direction (3), tmax.
"""

import numpy as np

# The integrator's default `render.ray_offset` (crates/scene/src/format.rs).
RAY_OFFSET = 1e-4


def orthonormal_basis(n):
    """Two unit vectors (t, b) completing each unit row of `n` (k x 3, f64) to a right-handed
    orthonormal frame (Duff et al. 2017, "Building an Orthonormal Basis, Revisited")."""
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bt


def cosine_directions(n, u, v):
    """Cosine-weighted unit directions about the unit normals `n` (k x 3, f64) from uniform
    numbers `u`, `v` in [0, 1) (k each): radius sqrt(u) and angle 2 pi v on the unit disk,
    lifted to height sqrt(1 - u). Returned in f64."""
    r = np.sqrt(u)
    phi = 2.0 * np.pi * v
    x, y = r * np.cos(phi), r * np.sin(phi)
    z = np.sqrt(np.maximum(0.0, 1.0 - u))
    t, b = orthonormal_basis(n)
    d = t * x[:, None] + b * y[:, None] + n * z[:, None]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def surface_points(camera_rays, t_hit, prim, tris, offset=RAY_OFFSET):
    """(origins, normals) of the camera rays' hits, in pixel order, f64: `camera_rays` is
    n x 6 float32 (origin, direction), `t_hit` the hit distances (+inf on a miss), `prim` the
    hit triangles' indices into `tris` (m x 3 x 3 float32). Normals are geometric, facing
    the camera ray; origins are offset along them as the integrator offsets its rays."""
    origins, normals, _ = surface_frames(camera_rays, t_hit, prim, tris, offset)
    return origins, normals


def surface_frames(camera_rays, t_hit, prim, tris, offset=RAY_OFFSET):
    """`surface_points` with the hit points themselves: (origins, normals, points)."""
    hit = np.isfinite(t_hit)
    o = camera_rays[hit, :3].astype(np.float64)
    d = camera_rays[hit, 3:].astype(np.float64)
    p = o + d * t_hit[hit, None].astype(np.float64)
    tri = tris[prim[hit].astype(np.int64)].astype(np.float64)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    # A degenerate triangle (no normal) takes the reversed ray direction.
    n = np.where(length > 0.0, n / np.where(length > 0.0, length, 1.0), -d)
    n = np.where((np.sum(n * d, axis=1) > 0.0)[:, None], -n, n)
    dist = np.maximum(np.linalg.norm(p, axis=1), 1e-30)
    return p + n * (offset * dist)[:, None], n, p


def light_above(lo, hi, size=0.25, height=0.5):
    """A square area light above the box `lo`..`hi` (render space, +y up as the anchor's
    camera frames the meshes): (corner, edge_u, edge_v) in f64, centred over the box at
    `height` box diagonals above its top (below it when negative: under the ceiling of a
    `boxed_obj` room), each side `size` diagonals long. It emits downwards (along
    edge_u x edge_v)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    diagonal = float(np.linalg.norm(hi - lo))
    centre = np.array([(lo[0] + hi[0]) / 2, hi[1] + height * diagonal, (lo[2] + hi[2]) / 2])
    side = size * diagonal
    u, v = np.array([side, 0.0, 0.0]), np.array([0.0, 0.0, side])
    return centre - (u + v) / 2, u, v


def shadow_rays(points, origins, normals, light, u, v, offset=RAY_OFFSET):
    """Shadow rays (k x 7 float32) from `points` (with their offset `origins` and `normals`,
    f64) towards the points `corner + u * edge_u + v * edge_v` of the rectangular `light`,
    each ending `offset * max(|p|, 1e-30)` short of it; rays whose light point lies on or
    behind the surface (n . d <= 0), and points behind the light (it emits along
    edge_u x edge_v only), are left out, as the integrators leave them out."""
    corner, eu, ev = (np.asarray(x, dtype=np.float64) for x in light)
    q = corner + u[:, None] * eu + v[:, None] * ev
    to = q - points
    dist = np.linalg.norm(to, axis=1)
    d = to / dist[:, None]
    keep = np.sum(d * normals, axis=1) > 0.0
    keep &= (points - corner) @ np.cross(eu, ev) > 0.0
    tmax = dist - offset * np.maximum(np.linalg.norm(points, axis=1), 1e-30)
    keep &= tmax > 0.0
    rays = np.empty((int(keep.sum()), 7), dtype=np.float32)
    rays[:, :3] = origins[keep]
    rays[:, 3:6] = d[keep]
    rays[:, 6] = tmax[keep]
    return rays


def incoherent_rays(camera_rays, t_hit, prim, tris, seed, ao_distance, per_hit=1,
                    offset=RAY_OFFSET, light=None):
    """{"ao": rays, "bounce": rays[, "shadow": rays]} (each k x 7 float32, k = hits x per_hit
    for AO and bounce rays; a hit's rays are consecutive) from the camera rays' hits (see
    `surface_points`), drawn from `seed`: AO rays end at `ao_distance`, bounce rays at +inf,
    and with a `light` (corner, edge_u, edge_v: see `light_above`) shadow rays towards it
    (`shadow_rays`), drawn after the others so AO and bounce rays do not depend on it."""
    if per_hit < 1:
        raise ValueError("per_hit must be at least 1")
    if not ao_distance > 0.0:
        raise ValueError("ao_distance must be positive")
    origins, normals, points = surface_frames(camera_rays, t_hit, prim, tris, offset)
    origins = np.repeat(origins, per_hit, axis=0)
    normals = np.repeat(normals, per_hit, axis=0)
    points = np.repeat(points, per_hit, axis=0)
    rng = np.random.Generator(np.random.PCG64(seed))
    out = {}
    for kind, tmax in (("ao", float(ao_distance)), ("bounce", np.inf)):
        u = rng.random(len(origins))
        v = rng.random(len(origins))
        rays = np.empty((len(origins), 7), dtype=np.float32)
        rays[:, :3] = origins
        rays[:, 3:6] = cosine_directions(normals, u, v)
        rays[:, 6] = tmax
        out[kind] = rays
    if light is not None:
        u = rng.random(len(origins))
        v = rng.random(len(origins))
        out["shadow"] = shadow_rays(points, origins, normals, light, u, v, offset)
    return out


def boxed_obj(src, dst, margin=0.15):
    """Writes to `dst` the OBJ `src` with five walls of an open cube around it appended (two
    triangles each, absolute indices after the file's vertices): a floor just below the mesh,
    a ceiling, a back wall (+z) and two side walls; the front (-z, where the anchor's camera
    stands) stays open. The cube's side is the mesh's largest extent times 1 + 2 `margin`,
    centred on the mesh in x and z. Returns the number of triangles added (10)."""
    with open(src) as f:
        text = f.read()
    verts = np.array(
        [[float(x) for x in line.split()[1:4]] for line in text.splitlines()
         if line.startswith("v ")],
        dtype=np.float64,
    )
    if len(verts) == 0:
        raise ValueError(f"{src}: no vertices")
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    side = float((hi - lo).max()) * (1.0 + 2.0 * margin)
    cx, cz = (lo[0] + hi[0]) / 2, (lo[2] + hi[2]) / 2
    x0, x1 = cx - side / 2, cx + side / 2
    z0, z1 = cz - side / 2, cz + side / 2
    y0 = lo[1] - 1e-3 * side
    y1 = y0 + side
    corners = [[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)]
    # Corner k: x = bit 2, y = bit 1, z = bit 0.
    quads = [(0, 4, 5, 1), (2, 3, 7, 6), (1, 5, 7, 3), (0, 1, 3, 2), (4, 6, 7, 5)]
    n = len(verts)
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in corners]
    for a, b, c, d in quads:
        lines.append(f"f {n + a + 1} {n + b + 1} {n + c + 1}")
        lines.append(f"f {n + a + 1} {n + c + 1} {n + d + 1}")
    with open(dst, "w") as f:
        f.write(text if text.endswith("\n") else text + "\n")
        f.write("# an open box around the mesh (scripts/anchor_incoherent.py boxed_obj)\n")
        f.write("\n".join(lines) + "\n")
    return 2 * len(quads)
