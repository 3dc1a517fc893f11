//! Counters a render accumulates over all rays.

use crate::geometry::{RayWork, Termination};

/// Ray counts, work and stability counters for one render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RenderStats {
    /// Camera rays traced (pixels x samples).
    pub primary_rays: u64,
    /// Occlusion rays traced.
    pub shadow_rays: u64,
    /// Mirror reflection rays traced (Whitted integrator).
    pub reflection_rays: u64,
    /// Ambient-occlusion rays traced.
    pub ao_rays: u64,
    /// Path-tracer scattering rays after the camera ray (diffuse and mirror bounces).
    pub bounce_rays: u64,
    /// Time spent inside the geometry's batch queries per ray type, summed over threads.
    pub trace_time: RayTypeTimes,
    /// Closest-hit queries that ended by step exhaustion.
    pub closest_max_steps: u64,
    /// Occlusion queries that ended by step exhaustion.
    pub occlusion_max_steps: u64,
    /// Queries that ended at the maximum distance.
    pub max_distance: u64,
    /// Closest-hit queries that ended with a hit.
    pub hits: u64,
    /// Sum of SDF steps over all queries.
    pub steps: u64,
    /// Largest SDF step count of any query.
    pub max_steps_seen: u32,
    /// Sum of BVH node visits over all queries.
    pub node_visits: u64,
    /// Largest node-visit count of any query.
    pub max_node_visits_seen: u32,
    /// Sum of primitive tests over all queries.
    pub primitive_tests: u64,
    /// Hits with a non-finite distance, position or normal (dropped as misses).
    pub non_finite_hits: u64,
    /// Pixels whose final colour had a NaN or infinite channel (written as black).
    pub non_finite_pixels: u64,
}

impl RenderStats {
    /// All rays traced.
    pub fn total_rays(&self) -> u64 {
        self.primary_rays
            + self.shadow_rays
            + self.reflection_rays
            + self.ao_rays
            + self.bounce_rays
    }

    /// Million rays per second of one thread, per ray type: rays of the type divided by the
    /// time the geometry spent tracing them (`None` for a type with no rays or no time).
    pub fn mrays_per_thread_second(&self) -> RayTypeRates {
        let rate = |rays: u64, ns: u64| (rays > 0 && ns > 0).then(|| rays as f64 * 1e3 / ns as f64);
        let t = &self.trace_time;
        RayTypeRates {
            camera: rate(self.primary_rays, t.camera_ns),
            shadow: rate(self.shadow_rays, t.shadow_ns),
            ambient_occlusion: rate(self.ao_rays, t.ambient_occlusion_ns),
            bounce: rate(self.reflection_rays + self.bounce_rays, t.bounce_ns),
        }
    }

    /// Fraction of all queries that ran out of steps, in [0, 1].
    pub fn step_exhaustion_rate(&self) -> f64 {
        let n = self.total_rays();
        if n == 0 {
            0.0
        } else {
            (self.closest_max_steps + self.occlusion_max_steps) as f64 / n as f64
        }
    }

    /// Mean SDF steps per ray.
    pub fn mean_steps(&self) -> f64 {
        self.steps as f64 / self.total_rays().max(1) as f64
    }

    /// Mean BVH node visits per ray.
    pub fn mean_node_visits(&self) -> f64 {
        self.node_visits as f64 / self.total_rays().max(1) as f64
    }

    pub(crate) fn add_work(&mut self, w: &RayWork) {
        self.steps += w.steps as u64;
        self.max_steps_seen = self.max_steps_seen.max(w.steps);
        self.node_visits += w.node_visits as u64;
        self.max_node_visits_seen = self.max_node_visits_seen.max(w.node_visits);
        self.primitive_tests += w.primitive_tests as u64;
    }

    pub(crate) fn add_termination(&mut self, t: Termination, occlusion: bool) {
        match t {
            Termination::Hit if !occlusion => self.hits += 1,
            Termination::MaxSteps if occlusion => self.occlusion_max_steps += 1,
            Termination::MaxSteps => self.closest_max_steps += 1,
            Termination::MaxDistance => self.max_distance += 1,
            _ => {}
        }
    }

    /// Adds another tile's counters to these.
    pub fn merge(&mut self, o: &RenderStats) {
        self.primary_rays += o.primary_rays;
        self.shadow_rays += o.shadow_rays;
        self.reflection_rays += o.reflection_rays;
        self.closest_max_steps += o.closest_max_steps;
        self.occlusion_max_steps += o.occlusion_max_steps;
        self.max_distance += o.max_distance;
        self.hits += o.hits;
        self.steps += o.steps;
        self.max_steps_seen = self.max_steps_seen.max(o.max_steps_seen);
        self.node_visits += o.node_visits;
        self.max_node_visits_seen = self.max_node_visits_seen.max(o.max_node_visits_seen);
        self.primitive_tests += o.primitive_tests;
        self.non_finite_hits += o.non_finite_hits;
        self.non_finite_pixels += o.non_finite_pixels;
        self.ao_rays += o.ao_rays;
        self.bounce_rays += o.bounce_rays;
        let (t, u) = (&mut self.trace_time, &o.trace_time);
        t.camera_ns += u.camera_ns;
        t.shadow_ns += u.shadow_ns;
        t.ambient_occlusion_ns += u.ambient_occlusion_ns;
        t.bounce_ns += u.bounce_ns;
    }
}

/// Nanoseconds spent in the geometry's batch queries, per ray type, summed over threads.
///
/// Camera rays are coherent; shadow rays towards area lights, ambient-occlusion rays and
/// path-tracer bounces are not: the split shows what each representation pays for each kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RayTypeTimes {
    /// Camera (primary) rays.
    pub camera_ns: u64,
    /// Occlusion rays towards lights.
    pub shadow_ns: u64,
    /// Ambient-occlusion rays.
    pub ambient_occlusion_ns: u64,
    /// Mirror reflections and path-tracer bounces.
    pub bounce_ns: u64,
}

/// Million rays per thread-second per ray type (see [`RenderStats::mrays_per_thread_second`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RayTypeRates {
    /// Camera rays.
    pub camera: Option<f64>,
    /// Shadow rays.
    pub shadow: Option<f64>,
    /// Ambient-occlusion rays.
    pub ambient_occlusion: Option<f64>,
    /// Reflection and bounce rays.
    pub bounce: Option<f64>,
}
