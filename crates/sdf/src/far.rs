//! Tracing with objects far from the camera ([`FarFrame`], decision record 0018): each ray
//! is traced through the render-space field and entered into every far object's frame it
//! can meet, the nearer hit kept with its distance reassembled in f64; without far objects
//! the render-space field alone answers (`near_*`).

use super::*;

impl SdfGeometry {
    /// [`Geometry::closest_hit`] through `field` alone.
    pub(crate) fn near_closest_hit(&self, ray: &Ray) -> TraceResult {
        if let Some(inside) = self.inside_of(ray) {
            return self.closest_from_inside(inside, ray);
        }
        match March::new(ray, &self.params, true) {
            Err(why) => TraceResult::not_found(why, RayWork::default()),
            Ok(mut m) => {
                let t = self.run(&mut m);
                self.finish(&m, t)
            }
        }
    }

    /// [`Geometry::occluded`] through `field` alone.
    pub(crate) fn near_occluded(&self, ray: &Ray) -> OcclusionResult {
        if let Some(inside) = self.inside_of(ray) {
            return match March::new(ray, &self.params, false) {
                Err(t) => OcclusionResult {
                    occluded: false,
                    termination: t.into(),
                    work: RayWork::default(),
                },
                Ok(mut m) => {
                    let t = Self::run_inside(&mut m, &self.params, inside);
                    Self::occ(&m, t)
                }
            };
        }
        match March::new(ray, &self.params, false) {
            Err(t) => OcclusionResult {
                occluded: false,
                termination: t.into(),
                work: RayWork::default(),
            },
            Ok(mut m) => {
                let t = self.run(&mut m);
                Self::occ(&m, t)
            }
        }
    }

    /// [`Geometry::closest_hits`] through `field` alone.
    pub(crate) fn near_closest_hits(&self, rays: &[Ray], out: &mut [TraceResult]) {
        assert_eq!(
            rays.len(),
            out.len(),
            "closest_hits: rays and out differ in length"
        );
        if !self.lockstep || self.inside.is_some() {
            for (r, o) in rays.iter().zip(out.iter_mut()) {
                *o = self.near_closest_hit(r);
            }
            return;
        }
        // Hits wait here for their normals, computed 8 at a time.
        let mut pending: Vec<PendingHit> = Vec::with_capacity(8);
        // Every pending hit comes from one bundle or from whole-field bundles: a bundle's end
        // flushes them.
        let flush = |scope: Scope<'_>, pending: &mut Vec<PendingHit>, out: &mut [TraceResult]| {
            if !pending.is_empty() {
                self.flush_normals(scope, pending, out);
            }
        };
        if !self.culls() {
            // The whole field for every ray (the common case of small scenes), without the
            // bundle events.
            self.lockstep_with(
                rays,
                0,
                true,
                &mut |i, m, t| {
                    if self.record((i, m, t), &mut pending, out) {
                        flush(Scope::Whole, &mut pending, out);
                    }
                },
                |p| self.field.distance_lanes(p),
                |p, d, len| self.field.segment_step(p, d, len),
                |p, d, len| self.field.segment_lanes(p, d, len),
                |p, d| self.field.recedes(p, d),
                self.field.has_tape(),
            );
            return flush(Scope::Whole, &mut pending, out);
        }
        self.lockstep(rays, true, |scope, event| match event {
            Event::BundleEnd => flush(scope, &mut pending, out),
            Event::Done(i, m, t) => {
                if self.record((i, m, t), &mut pending, out) {
                    flush(scope, &mut pending, out);
                }
            }
        });
    }

    /// [`Geometry::occluded_many`] through `field` alone.
    pub(crate) fn near_occluded_many(&self, rays: &[Ray], out: &mut [OcclusionResult]) {
        assert_eq!(
            rays.len(),
            out.len(),
            "occluded_many: rays and out differ in length"
        );
        if !self.lockstep || self.inside.is_some() {
            for (r, o) in rays.iter().zip(out.iter_mut()) {
                *o = self.near_occluded(r);
            }
            return;
        }
        self.lockstep(rays, false, |_, event| {
            let Event::Done(i, m, t) = event else {
                return;
            };
            out[i] = match m {
                Some(m) => Self::occ(m, t),
                None => OcclusionResult {
                    occluded: false,
                    termination: t,
                    work: RayWork::default(),
                },
            };
        });
    }

    /// The closest hits of `rays` through the render-space field and every far part: each
    /// far part traces the rays entering its bounding sphere before the best hit so far,
    /// started there in its frame ([`FarFrame::enter`]; primary rays along their exact f64
    /// directions from `samples`), its hits' distances and points reassembled in f64.
    pub(crate) fn closest_hits_far(
        &self,
        rays: &[Ray],
        samples: Option<PrimarySamples<'_>>,
        out: &mut [TraceResult],
    ) {
        assert_eq!(
            rays.len(),
            out.len(),
            "closest_hits: rays and out differ in length"
        );
        if self.near {
            self.near_closest_hits(rays, out);
        } else {
            out.fill(TraceResult::not_found(NoHit::Miss, RayWork::default()));
        }
        let mut local: Vec<Ray> = Vec::new();
        let mut entries: Vec<(usize, FrameEntry)> = Vec::new();
        let mut local_out: Vec<TraceResult> = Vec::new();
        for far in &self.far {
            local.clear();
            entries.clear();
            for (i, ray) in rays.iter().enumerate() {
                let t_max = out[i]
                    .hit()
                    .map_or(ray.t_max, |h| h.t)
                    .min(self.params.max_distance);
                let dir = samples.map_or_else(|| ray.dir.as_dvec3(), |s| s.direction(i));
                if let Some(e) = far.frame.enter(ray.origin, dir, ray.t_min, t_max) {
                    local.push(e.local_ray(far.frame.centre(), ray.dir));
                    entries.push((i, e));
                }
            }
            if local.is_empty() {
                continue;
            }
            local_out.clear();
            local_out.resize(
                local.len(),
                TraceResult::not_found(NoHit::Miss, RayWork::default()),
            );
            far.part.near_closest_hits(&local, &mut local_out);
            for (&(i, e), r) in entries.iter().zip(&local_out) {
                out[i] = merge_far_hit(out[i], *r, &e, far.frame.centre());
            }
        }
    }

    /// [`Geometry::occluded_many`] through the render-space field and every far part (the
    /// rays not yet occluded, entering each part's bounding sphere).
    pub(crate) fn occluded_far(&self, rays: &[Ray], out: &mut [OcclusionResult]) {
        assert_eq!(
            rays.len(),
            out.len(),
            "occluded_many: rays and out differ in length"
        );
        if self.near {
            self.near_occluded_many(rays, out);
        } else {
            out.fill(OcclusionResult {
                occluded: false,
                termination: Termination::Miss,
                work: RayWork::default(),
            });
        }
        let mut local: Vec<Ray> = Vec::new();
        let mut index: Vec<usize> = Vec::new();
        let mut local_out: Vec<OcclusionResult> = Vec::new();
        for far in &self.far {
            local.clear();
            index.clear();
            for (i, ray) in rays.iter().enumerate() {
                if out[i].occluded {
                    continue;
                }
                let t_max = ray.t_max.min(self.params.max_distance);
                if let Some(e) = far
                    .frame
                    .enter(ray.origin, ray.dir.as_dvec3(), ray.t_min, t_max)
                {
                    local.push(e.local_ray(far.frame.centre(), ray.dir));
                    index.push(i);
                }
            }
            if local.is_empty() {
                continue;
            }
            local_out.clear();
            local_out.resize(local.len(), OcclusionResult::default());
            far.part.near_occluded_many(&local, &mut local_out);
            for (&i, r) in index.iter().zip(&local_out) {
                let o = &mut out[i];
                o.work.steps += r.work.steps;
                if r.occluded {
                    o.occluded = true;
                    o.termination = Termination::Hit;
                } else if r.termination == Termination::MaxSteps {
                    o.termination = Termination::MaxSteps;
                }
            }
        }
    }
}

/// `best` (render space) and `local`, the result of the same ray traced in a far frame
/// centred on `centre` from `entry`, merged: the nearer hit (its distance and point
/// reassembled in f64), else step exhaustion if either ran out; work added.
fn merge_far_hit(
    best: TraceResult,
    local: TraceResult,
    entry: &FrameEntry,
    centre: DVec3,
) -> TraceResult {
    let work = RayWork {
        steps: best.work.steps + local.work.steps,
        ..best.work
    };
    match (best.hit(), local.hit()) {
        (best_hit, Some(h)) => {
            let t = entry.render_t(h.t);
            match best_hit {
                Some(b) if b.t < t => TraceResult::found(b, work),
                _ => TraceResult::found(
                    Hit {
                        t,
                        position: (centre + h.position.as_dvec3()).as_vec3(),
                        ..h
                    },
                    work,
                ),
            }
        }
        (Some(b), None) => TraceResult::found(b, work),
        (None, None) => {
            let why = if local.termination() == Termination::MaxSteps {
                NoHit::MaxSteps
            } else {
                NoHit::try_from(best.termination()).unwrap_or(NoHit::Miss)
            };
            TraceResult::not_found(why, work)
        }
    }
}
