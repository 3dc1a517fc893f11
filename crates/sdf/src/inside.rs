//! Rays that start inside a solid.
//!
//! The scene semantics (`scenes/README.md`): top-level objects are independent surfaces and a
//! ray sees the first boundary crossing of any of them, even from inside another one. The
//! union field the tracer marches cannot show a surface that lies inside another solid (the
//! union has no boundary there), so when the camera is inside a solid the backend also keeps
//! one field per top-level object, and rays that start inside march the distance to the
//! nearest top-level surface with the same state machine: `min_k o_k d_k`, each object's
//! distance oriented by its sign where the ray starts (`o_k = -1` inside it, `+1` outside), so
//! the first crossing of any top-level surface is a sign change the tracer brackets. Only an
//! object whose surface the ray starts on (within the shell: a secondary ray leaving it) has
//! no known side and enters unsigned, `|d_k|`, a sheet, which the tracer also handles. (With
//! every object unsigned, a ray running within the shell along one surface and leaving
//! through another where they meet, as at the seam where a removed sphere cuts a box's face,
//! had no sign change to find and could walk out through the exit.) What is not visible gets
//! no secondary rays, so a camera outside every solid never needs this.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::{Field, FieldError, FieldOptions};
use marchmesh_scene::{MaterialId, Scene};

/// Most top-level objects kept as separate fields; beyond it a camera inside a solid sees the
/// union's boundary (said in the report's notes).
pub(crate) const MAX_INSIDE_OBJECTS: usize = 256;

/// How each top-level object's distance enters one ray's march ([`Inside::sides`]): bit `k`
/// of `flip` set when the ray starts inside object `k` (its distance is negated), of `sheet`
/// when it starts on its surface (its distance enters unsigned).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Sides {
    flip: [u64; MAX_INSIDE_OBJECTS / 64],
    sheet: [u64; MAX_INSIDE_OBJECTS / 64],
}

impl Sides {
    #[inline]
    fn bit(words: &[u64; MAX_INSIDE_OBJECTS / 64], k: usize) -> bool {
        words[k / 64] >> (k % 64) & 1 == 1
    }

    /// Object `k`'s distance `d` oriented for the ray.
    #[inline]
    fn orient(&self, k: usize, d: f32) -> f32 {
        if Self::bit(&self.sheet, k) {
            d.abs()
        } else if Self::bit(&self.flip, k) {
            -d
        } else {
            d
        }
    }
}

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

    /// The sides of every object at a ray's first sample point `start`: the surfaces within
    /// `shell` of it are sheets (the ray starts on them), the others signed, positive at
    /// `start`.
    pub(crate) fn sides(&self, start: Vec3, shell: f32) -> Sides {
        let mut sides = Sides::default();
        for (k, f) in self.objects.iter().enumerate() {
            let d = f.distance(start);
            let bit = 1u64 << (k % 64);
            if d.abs() < shell || d.is_nan() {
                sides.sheet[k / 64] |= bit;
            } else if d < 0.0 {
                sides.flip[k / 64] |= bit;
            }
        }
        sides
    }

    /// The distance a ray with `sides` marches: `min_k` of the objects' oriented distances
    /// (positive before the ray's first crossing of a top-level surface, negative just after
    /// it unless that surface is a sheet).
    #[inline]
    pub(crate) fn oriented(&self, p: Vec3, sides: &Sides) -> f32 {
        let mut best = f32::INFINITY;
        for (k, f) in self.objects.iter().enumerate() {
            best = best.min(sides.orient(k, f.distance(p)));
        }
        best
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
