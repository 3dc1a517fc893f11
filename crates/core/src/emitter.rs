//! Area lights in render space: sampling a point on a light as seen from a shading point, and
//! intersecting rays with lights.
//!
//! Lights are not geometry: backends never see them, they cast no shadows and occlusion rays
//! pass through them. The integrators intersect them in closed form so that camera rays and
//! mirror paths see their emission.

use glam::Vec3;
use marchmesh_scene::Light;

use crate::geometry::RenderSpace;
use crate::sampling::uniform_cone;

/// An area light, render space, f32.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Emitter {
    /// A sphere emitting on its whole surface.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius (> 0).
        radius: f32,
        /// Per-channel intensity (Whitted) or radiance (path tracer).
        emission: Vec3,
        /// Whether occlusion rays are traced towards it.
        casts_shadows: bool,
    },
    /// A parallelogram emitting on the side its `normal` points to.
    Rectangle {
        /// Corner.
        corner: Vec3,
        /// First edge.
        edge_u: Vec3,
        /// Second edge.
        edge_v: Vec3,
        /// Unit normal `normalize(cross(edge_u, edge_v))`: the emitting side.
        normal: Vec3,
        /// Area (> 0).
        area: f32,
        /// Per-channel intensity (Whitted) or radiance (path tracer).
        emission: Vec3,
        /// Whether occlusion rays are traced towards it.
        casts_shadows: bool,
    },
}

/// Most cones [`Emitter::cones_from`] splits a light into.
pub const MAX_LIGHT_CONES: usize = 4;

/// Tangent of the half angle beyond which [`Emitter::cones_from`] splits a squarish light
/// into four cones: one cone's penumbra estimate degrades as it widens (the stability
/// study's `shadow_light_size` and `shadow_sphere_light` families measure it).
pub const CONE_SPLIT_TAN: f32 = 0.15;

/// A cone from a shading point towards (part of) a light.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LightCone {
    /// Unit axis.
    pub dir: Vec3,
    /// Distance to the part's centre along the axis.
    pub dist: f32,
    /// Tangent of the half opening angle.
    pub tan_half_angle: f32,
    /// The part's share of the light's solid angle (the weights of one light sum to 1).
    pub weight: f32,
}

/// A point on a light chosen for a shading point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSample {
    /// Unit direction from the shading point towards the light point.
    pub dir: Vec3,
    /// Distance from the shading point to the light point.
    pub dist: f32,
    /// Probability density of the sampled direction per unit solid angle (> 0).
    pub pdf_solid_angle: f32,
}

impl Emitter {
    /// The area light of `light` in `space`, or `None` for point, directional and ambient
    /// lights.
    pub fn of(light: &Light, space: &RenderSpace) -> Option<Self> {
        match *light {
            Light::Sphere {
                center,
                radius,
                emission,
                casts_shadows,
            } => Some(Emitter::Sphere {
                center: space.point(center).as_vec3(),
                radius: radius as f32,
                emission: emission.as_vec3(),
                casts_shadows,
            }),
            Light::Rectangle {
                corner,
                edge_u,
                edge_v,
                emission,
                casts_shadows,
            } => {
                let cross = edge_u.cross(edge_v);
                Some(Emitter::Rectangle {
                    corner: space.point(corner).as_vec3(),
                    edge_u: edge_u.as_vec3(),
                    edge_v: edge_v.as_vec3(),
                    normal: cross.normalize().as_vec3(),
                    area: cross.length() as f32,
                    emission: emission.as_vec3(),
                    casts_shadows,
                })
            }
            Light::Ambient { .. } | Light::Point { .. } | Light::Directional { .. } => None,
        }
    }

    /// Per-channel emission.
    pub fn emission(&self) -> Vec3 {
        match *self {
            Emitter::Sphere { emission, .. } | Emitter::Rectangle { emission, .. } => emission,
        }
    }

    /// Whether occlusion rays are traced towards the light.
    pub fn casts_shadows(&self) -> bool {
        match *self {
            Emitter::Sphere { casts_shadows, .. } | Emitter::Rectangle { casts_shadows, .. } => {
                casts_shadows
            }
        }
    }

    /// A point on the light as seen from `p`, from two uniform numbers `(u, v)`.
    ///
    /// Sphere: uniform over the solid angle the sphere subtends at `p` (pbrt-v3, "Sampling
    /// Spheres"); `None` when `p` is inside the sphere (it receives no light from it).
    /// Rectangle: uniform over its area, converted to solid angle; `None` when `p` is behind
    /// the emitting side or the point is degenerate.
    pub fn sample(&self, p: Vec3, u: f32, v: f32) -> Option<LightSample> {
        match *self {
            Emitter::Sphere { center, radius, .. } => {
                let to_center = center - p;
                let d2 = to_center.length_squared();
                let r2 = radius * radius;
                if d2 <= r2 {
                    return None;
                }
                let d = d2.sqrt();
                let axis = to_center / d;
                // 1 - cos(half angle) = (r/d)^2 / (1 + cos): no cancellation for tiny lights.
                let sin2_max = r2 / d2;
                let one_minus_cos_max = sin2_max / (1.0 + (1.0 - sin2_max).max(0.0).sqrt());
                let dir = uniform_cone(axis, one_minus_cos_max, u, v);
                // First intersection of p + t dir with the sphere (the near side).
                let b = dir.dot(to_center);
                let disc = (r2 - (d2 - b * b)).max(0.0);
                let dist = (b - disc.sqrt()).max(0.0);
                let solid_angle = 2.0 * std::f32::consts::PI * one_minus_cos_max;
                (solid_angle > 0.0 && dist > 0.0).then(|| LightSample {
                    dir,
                    dist,
                    pdf_solid_angle: 1.0 / solid_angle,
                })
            }
            Emitter::Rectangle {
                corner,
                edge_u,
                edge_v,
                normal,
                area,
                ..
            } => {
                let q = corner + edge_u * u + edge_v * v;
                let to = q - p;
                let dist = to.length();
                if dist.is_nan() || dist <= 0.0 {
                    return None;
                }
                let dir = to / dist;
                let cos_light = -normal.dot(dir);
                (cos_light > 0.0).then(|| LightSample {
                    dir,
                    dist,
                    pdf_solid_angle: dist * dist / (area * cos_light),
                })
            }
        }
    }

    /// Cones from `p` that together subtend about the light's solid angle, for one-query
    /// visibility estimates: the first `count` entries of the array, with weights (each part's
    /// share of the solid angle) summing to 1 (exactly 1 for one cone). A cone's penumbra
    /// estimate degrades as it widens and is round whatever the light's shape, so:
    /// - a sphere is one exact cone, or four (its disk's quadrants, each the disk of a
    ///   quarter of its area around the quadrant's centroid) when its half angle's tangent is
    ///   over [`CONE_SPLIT_TAN`];
    /// - a rectangle is split along its longer edge into `min(round(aspect),`
    ///   [`MAX_LIGHT_CONES`]`)` parts of aspect near 1, and a squarish one whose disk is
    ///   wider than [`CONE_SPLIT_TAN`] into 2 x 2; each part is the disk of its projected area.
    ///
    /// Empty when `p` is inside the sphere or behind the rectangle.
    pub fn cones_from(&self, p: Vec3) -> ([LightCone; MAX_LIGHT_CONES], usize) {
        let mut cones = [LightCone::default(); MAX_LIGHT_CONES];
        match *self {
            Emitter::Sphere { center, radius, .. } => {
                let to = center - p;
                let d2 = to.length_squared();
                let r2 = radius * radius;
                if d2 <= r2 {
                    return (cones, 0);
                }
                let d = d2.sqrt();
                let dir = to / d;
                let tan_half_angle = radius / (d2 - r2).sqrt();
                if tan_half_angle <= CONE_SPLIT_TAN {
                    cones[0] = LightCone {
                        dir,
                        dist: d,
                        tan_half_angle,
                        weight: 1.0,
                    };
                    return (cones, 1);
                }
                // Quadrants of the disk of angular radius `alpha`: each centroid lies
                // 4 alpha / (3 pi) from the centre along both axes, each quarter disk is
                // replaced by the disk of its area (angular radius alpha / 2).
                let alpha = tan_half_angle.atan();
                let off = 4.0 * alpha / (3.0 * std::f32::consts::PI);
                let (b1, b2) = dir.any_orthonormal_pair();
                let tan_part = (0.5 * alpha).tan();
                for (cone, (sx, sy)) in
                    cones
                        .iter_mut()
                        .zip([(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)])
                {
                    let axis = (dir + off.tan() * (sx * b1 + sy * b2)).normalize();
                    *cone = LightCone {
                        dir: axis,
                        dist: d,
                        tan_half_angle: tan_part,
                        weight: 0.25,
                    };
                }
                (cones, 4)
            }
            Emitter::Rectangle {
                corner,
                edge_u,
                edge_v,
                normal,
                area,
                ..
            } => {
                let (long, short) = if edge_u.length_squared() >= edge_v.length_squared() {
                    (edge_u, edge_v)
                } else {
                    (edge_v, edge_u)
                };
                let aspect = (long.length() / short.length()).round();
                let mut along = if aspect.is_finite() && aspect >= 1.0 {
                    (aspect as usize).min(MAX_LIGHT_CONES)
                } else {
                    1
                };
                let mut across = 1;
                if along == 1 {
                    let to = corner + 0.5 * (long + short) - p;
                    let d = to.length();
                    let cos_light = -normal.dot(to / d);
                    let tan_whole = (area * cos_light.max(0.0) / std::f32::consts::PI).sqrt() / d;
                    if tan_whole > CONE_SPLIT_TAN {
                        (along, across) = (2, 2);
                    }
                }
                let parts = along * across;
                let part_area = area / parts as f32;
                let mut total = 0.0f32;
                for (k, cone) in cones.iter_mut().enumerate().take(parts) {
                    let (i, j) = (k % along, k / along);
                    let centre = corner
                        + (i as f32 + 0.5) / along as f32 * long
                        + (j as f32 + 0.5) / across as f32 * short;
                    let to = centre - p;
                    let d = to.length();
                    let dir = to / d;
                    let cos_light = -normal.dot(dir);
                    if d.is_nan() || d <= 0.0 || cos_light.is_nan() || cos_light <= 0.0 {
                        return (cones, 0);
                    }
                    let radius = (part_area * cos_light / std::f32::consts::PI).sqrt();
                    let weight = part_area * cos_light / (d * d);
                    total += weight;
                    *cone = LightCone {
                        dir,
                        dist: d,
                        tan_half_angle: radius / d,
                        weight,
                    };
                }
                if !(total.is_finite() && total > 0.0) {
                    return (cones, 0);
                }
                for cone in cones.iter_mut().take(parts) {
                    cone.weight /= total;
                }
                (cones, parts)
            }
        }
    }

    /// The distance along the ray `origin + t dir` (unit `dir`) at which it meets the light's
    /// emitting side, if within `(0, t_max)`.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<f32> {
        let t = match *self {
            Emitter::Sphere { center, radius, .. } => {
                let oc = center - origin;
                let b = dir.dot(oc);
                let c = oc.length_squared() - radius * radius;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                if b - s > 0.0 { b - s } else { b + s }
            }
            Emitter::Rectangle {
                corner,
                edge_u,
                edge_v,
                normal,
                ..
            } => {
                let denom = normal.dot(dir);
                // Only the emitting side faces the ray (the ray travels against the normal).
                if denom.is_nan() || denom >= 0.0 {
                    return None;
                }
                let t = normal.dot(corner - origin) / denom;
                let rel = origin + dir * t - corner;
                // Coordinates of the hit in the (edge_u, edge_v) frame by the dual basis.
                let (uu, uv, vv) = (edge_u.dot(edge_u), edge_u.dot(edge_v), edge_v.dot(edge_v));
                let det = uu * vv - uv * uv;
                let (ru, rv) = (rel.dot(edge_u), rel.dot(edge_v));
                let s = (ru * vv - rv * uv) / det;
                let w = (rv * uu - ru * uv) / det;
                if !((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&w)) {
                    return None;
                }
                t
            }
        };
        (t > 0.0 && t < t_max).then_some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Emitter {
        // A 2x2 square at y = 2 emitting downwards: cross(x, z) = -y.
        let edge_u = Vec3::new(2.0, 0.0, 0.0);
        let edge_v = Vec3::new(0.0, 0.0, 2.0);
        Emitter::Rectangle {
            corner: Vec3::new(-1.0, 2.0, -1.0),
            edge_u,
            edge_v,
            normal: edge_u.cross(edge_v).normalize(),
            area: 4.0,
            emission: Vec3::ONE,
            casts_shadows: true,
        }
    }

    #[test]
    fn a_square_is_one_cone_and_a_long_rectangle_one_per_squarish_part() {
        // The 2 x 2 square seen head-on from 10 units: one cone, the disk of its area.
        let far = Vec3::new(0.0, -8.0, 0.0);
        let (cones, n) = square().cones_from(far);
        assert_eq!(n, 1);
        assert_eq!(cones[0].weight, 1.0);
        assert_eq!(cones[0].dir, Vec3::Y);
        let want = (4.0 / std::f32::consts::PI).sqrt() / 10.0;
        assert!((cones[0].tan_half_angle - want).abs() < 1e-6);
        // From 2 units the disk is wider than CONE_SPLIT_TAN: four equal quarters.
        let (cones, n) = square().cones_from(Vec3::ZERO);
        assert_eq!(n, 4);
        for c in &cones {
            assert!((c.weight - 0.25).abs() < 1e-6);
            // Towards a quarter's centre (+-0.5, 2, +-0.5).
            let q = Vec3::new(0.5 * c.dir.x.signum(), 2.0, 0.5 * c.dir.z.signum());
            assert!(c.dir.dot(q.normalize()) > 0.999_99, "{:?}", c.dir);
        }

        // 8 x 1 at y = 2: split into MAX_LIGHT_CONES parts along x.
        let edge_u = Vec3::new(8.0, 0.0, 0.0);
        let edge_v = Vec3::new(0.0, 0.0, 1.0);
        let long = Emitter::Rectangle {
            corner: Vec3::new(-4.0, 2.0, -0.5),
            edge_u,
            edge_v,
            normal: edge_u.cross(edge_v).normalize(),
            area: 8.0,
            emission: Vec3::ONE,
            casts_shadows: true,
        };
        let (cones, n) = long.cones_from(Vec3::ZERO);
        assert_eq!(n, MAX_LIGHT_CONES);
        let sum: f32 = cones[..n].iter().map(|c| c.weight).sum();
        assert!((sum - 1.0).abs() < 1e-6, "{sum}");
        // Seen from below the centre: the inner parts subtend more than the outer ones, and
        // the split is symmetric.
        assert!(cones[1].weight > cones[0].weight);
        assert!((cones[0].weight - cones[3].weight).abs() < 1e-6);
        assert!(cones[0].dir.x < 0.0 && cones[3].dir.x > 0.0);
        // Behind the light: nothing.
        assert_eq!(long.cones_from(Vec3::new(0.0, 3.0, 0.0)).1, 0);
        // A sphere: one exact cone when narrow, its quadrants when wide, none from inside.
        let sphere = |radius: f32| Emitter::Sphere {
            center: Vec3::new(0.0, 2.0, 0.0),
            radius,
            emission: Vec3::ONE,
            casts_shadows: true,
        };
        let (cones, n) = sphere(0.2).cones_from(Vec3::ZERO);
        assert_eq!(n, 1);
        assert!((cones[0].tan_half_angle - 0.2 / (4.0f32 - 0.04).sqrt()).abs() < 1e-6);
        let (cones, n) = sphere(1.0).cones_from(Vec3::ZERO);
        assert_eq!(n, 4);
        let alpha = (1.0f32 / 3f32.sqrt()).atan();
        for c in &cones {
            assert_eq!(c.weight, 0.25);
            assert!((c.tan_half_angle - (0.5 * alpha).tan()).abs() < 1e-6);
            // Each quadrant's axis stays inside the sphere's disk.
            assert!(c.dir.dot(Vec3::Y) > alpha.cos());
        }
        let mean: Vec3 = cones.iter().map(|c| c.dir).sum::<Vec3>() / 4.0;
        assert!(mean.normalize().dot(Vec3::Y) > 0.999_99);
        assert_eq!(sphere(1.0).cones_from(Vec3::new(0.0, 2.5, 0.0)).1, 0);
    }

    #[test]
    fn rectangle_is_seen_from_its_emitting_side_only() {
        let e = square();
        assert_eq!(e.intersect(Vec3::ZERO, Vec3::Y, 10.0), Some(2.0));
        assert_eq!(e.intersect(Vec3::new(0.0, 4.0, 0.0), -Vec3::Y, 10.0), None);
        assert_eq!(e.intersect(Vec3::new(1.5, 0.0, 0.0), Vec3::Y, 10.0), None);
        assert!(e.sample(Vec3::ZERO, 0.5, 0.5).is_some());
        assert!(e.sample(Vec3::new(0.0, 3.0, 0.0), 0.5, 0.5).is_none());
    }

    #[test]
    fn rectangle_solid_angle_pdf_integrates_to_its_solid_angle() {
        // Mean of 1/pdf over uniform samples = the solid angle the square subtends.
        // A rectangle a x b centred at distance d above the point subtends
        // 4 asin(ab / sqrt((a^2 + 4d^2)(b^2 + 4d^2))).
        let e = square();
        let n = 256;
        let mut sum = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                let s = e
                    .sample(
                        Vec3::ZERO,
                        (i as f32 + 0.5) / n as f32,
                        (j as f32 + 0.5) / n as f32,
                    )
                    .unwrap();
                sum += 1.0 / s.pdf_solid_angle as f64;
            }
        }
        let expect = 4.0 * (4.0f64 / ((4.0 + 16.0f64) * (4.0 + 16.0)).sqrt()).asin();
        assert!((sum / (n * n) as f64 - expect).abs() < 1e-3 * expect);
    }

    #[test]
    fn sphere_samples_lie_on_the_sphere_facing_the_point() {
        let e = Emitter::Sphere {
            center: Vec3::new(0.0, 5.0, 0.0),
            radius: 1.0,
            emission: Vec3::ONE,
            casts_shadows: true,
        };
        for k in 0..100 {
            let s = e.sample(Vec3::ZERO, k as f32 / 100.0, 0.37).unwrap();
            let q = s.dir * s.dist;
            assert!(((q - Vec3::new(0.0, 5.0, 0.0)).length() - 1.0).abs() < 1e-4);
            assert!(q.y < 5.0, "the near side");
        }
        assert!(e.sample(Vec3::new(0.0, 5.2, 0.0), 0.5, 0.5).is_none());
        assert!((e.intersect(Vec3::ZERO, Vec3::Y, 10.0).unwrap() - 4.0).abs() < 1e-6);
    }
}
