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

    /// The cone from `p` towards the light's centre that subtends about the light's solid
    /// angle: `(unit axis, distance to the centre, tangent of the half angle)`. A sphere's cone
    /// is exact; a rectangle becomes the disk of its projected area. `None` when `p` is
    /// inside the sphere or behind the rectangle.
    pub fn cone_from(&self, p: Vec3) -> Option<(Vec3, f32, f32)> {
        match *self {
            Emitter::Sphere { center, radius, .. } => {
                let to = center - p;
                let d2 = to.length_squared();
                let r2 = radius * radius;
                if d2 <= r2 {
                    return None;
                }
                let d = d2.sqrt();
                Some((to / d, d, radius / (d2 - r2).sqrt()))
            }
            Emitter::Rectangle {
                corner,
                edge_u,
                edge_v,
                normal,
                area,
                ..
            } => {
                let to = corner + 0.5 * (edge_u + edge_v) - p;
                let d = to.length();
                let dir = to / d;
                let cos_light = -normal.dot(dir);
                if d.is_nan() || d <= 0.0 || cos_light.is_nan() || cos_light <= 0.0 {
                    return None;
                }
                let radius = (area * cos_light / std::f32::consts::PI).sqrt();
                Some((dir, d, radius / d))
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
