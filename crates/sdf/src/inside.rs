//! Rays that start inside a solid.
//!
//! The scene semantics (`scenes/README.md`): top-level objects are independent surfaces and a
//! ray sees the first boundary crossing of any of them, even from inside another one. The
//! union field the tracer marches cannot show a surface that lies inside another solid (the
//! union has no boundary there), so when the camera is inside a solid the backend also keeps
//! one field per top-level object, and rays that start inside march the unsigned distance to
//! the nearest top-level surface, `min_k |d_k|`, with the same state machine (every surface
//! then behaves like a sheet, which the tracer already handles). What is not visible gets no
//! secondary rays, so a camera outside every solid never needs this.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::{Field, FieldError, FieldOptions};
use marchmesh_scene::{MaterialId, Scene};

/// Most top-level objects kept as separate fields; beyond it a camera inside a solid sees the
/// union's boundary (said in the report's notes).
pub(crate) const MAX_INSIDE_OBJECTS: usize = 256;

/// One field per top-level object, for rays starting inside a solid.
#[derive(Debug)]
pub(crate) struct Inside {
    objects: Vec<Field>,
}

impl Inside {
    /// The per-object fields of `scene` when its camera is inside a solid of `union` (the
    /// scene's compiled field), `Ok(None)` otherwise or when there are too many objects.
    pub(crate) fn build(
        scene: &Scene,
        union: &Field,
        opts: &FieldOptions,
    ) -> Result<Option<Inside>, FieldError> {
        let camera_inside = union.distance_f64(DVec3::ZERO) < 0.0;
        if !camera_inside || scene.objects.len() > MAX_INSIDE_OBJECTS {
            return Ok(None);
        }
        let from_world = DAffine3::from_translation(-scene.camera.position);
        let objects = scene
            .objects
            .iter()
            .map(|n| Field::compile_node(n, from_world, opts))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Some(Inside { objects }))
    }

    /// Bytes of the per-object fields.
    pub(crate) fn memory_bytes(&self) -> u64 {
        self.objects.iter().map(Field::memory_bytes).sum()
    }

    /// Number of per-object fields.
    pub(crate) fn len(&self) -> usize {
        self.objects.len()
    }

    /// Unsigned distance to the nearest top-level surface, and that object's index.
    #[inline]
    pub(crate) fn nearest(&self, p: Vec3) -> (f32, usize) {
        let mut best = (f32::INFINITY, 0);
        for (k, f) in self.objects.iter().enumerate() {
            let d = f.distance(p).abs();
            if d < best.0 {
                best = (d, k);
            }
        }
        best
    }

    /// Unit outward normal of object `k` at `p` by central differences of step `h` (the
    /// integrator turns it to face the ray), and its material just in front of `p` along
    /// `-dir`; `-dir` when the gradient vanishes.
    pub(crate) fn normal_material(
        &self,
        k: usize,
        p: Vec3,
        dir: Vec3,
        h: f32,
    ) -> (Vec3, MaterialId) {
        let f = &self.objects[k];
        let (x, y, z) = (Vec3::X * h, Vec3::Y * h, Vec3::Z * h);
        let d = f.distance_x8([p + x, p - x, p + y, p - y, p + z, p - z, p, p]);
        let g = Vec3::new(d[0] - d[1], d[2] - d[3], d[4] - d[5]);
        let material = f.distance_material(p - dir * (2.0 * h)).1;
        let len = g.length();
        if len > 0.0 && len.is_finite() {
            (g / len, material)
        } else {
            (-dir, material)
        }
    }
}
