//! The quality knob: one `key=value` option per backend that `+`/`-` scale, as the backend
//! declares it ([`marchmesh_core::Backend::quality_knob`], read through the registry):
//!
//! - sdf: the hit epsilon, `eps_px` (fraction of the pixel footprint; `eps_abs` in world
//!   units instead when the user gave it). Level `q` divides it by `2^q`.
//! - mesh: the tessellation budget, `tess_px` (on-screen chord error in pixels; `tess_chord`
//!   in world units, or `tess_level` + `q` segments doublings, when the user gave those).
//!   Level `q` divides the error by `2^q`.
//! - reference: exact, no knob.
//!
//! The knob's option is appended after the user's options (later keys override earlier ones),
//! so the backend is built through the same registry and settings types as `marchmesh render
//! --opt KEY=VALUE`, and [`Knob::option`] is exactly the option that reproduces it.

use marchmesh_core::QualityKnob;
use marchmesh_registry::{BackendError, BackendId, BackendSpec};

/// The knob of one backend at level 0 (`None`: the backend has none).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Knob(pub Option<QualityKnob>);

impl Knob {
    /// The knob of `kind` given the user's `key=value` options (validated here: an unknown key
    /// or a bad value is the registry's error).
    pub fn of(kind: BackendId, user: &[(String, String)]) -> Result<Knob, BackendError> {
        kind.quality_knob(user).map(Knob)
    }

    /// The option that sets the knob to `level`, `None` without a knob.
    pub fn option(&self, level: i32) -> Option<(String, String)> {
        self.0.as_ref().map(|k| k.option(level))
    }

    /// The knob at `level` as overlay text, e.g. `eps_px=0.125 q+1` (the value's unit is
    /// in the key: `_px` pixels, `eps_abs`/`tess_chord` world units).
    pub fn describe(&self, level: i32) -> String {
        match self.option(level) {
            Some((k, v)) => format!("{k}={v} q{level:+}"),
            None => "exact".to_string(),
        }
    }
}

/// The backend spec of `kind` at quality `level`: the user's options, then the knob's.
pub fn spec(kind: BackendId, user: &[(String, String)], knob: &Knob, level: i32) -> BackendSpec {
    let mut options = user.to_vec();
    options.extend(knob.option(level));
    BackendSpec { kind, options }
}

#[cfg(test)]
mod tests {
    use super::*;
    use marchmesh_mesh::MeshBackend;
    use marchmesh_registry as backend;
    use marchmesh_sdf::SdfBackend;

    const SDF: BackendId = BackendId::of::<SdfBackend>();
    const MESH: BackendId = BackendId::of::<MeshBackend>();

    fn pairs(p: &[(&str, &str)]) -> Vec<(String, String)> {
        p.iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn sdf_knob_halves_the_pixel_epsilon() {
        let k = Knob::of(SDF, &[]).expect("knob");
        // Level 0 is the backend's default hit shell (`SdfOptions::DEFAULT`, 0.05 px).
        assert_eq!(k.option(0), Some(("eps_px".into(), "0.05".into())));
        assert_eq!(k.option(1), Some(("eps_px".into(), "0.025".into())));
        assert_eq!(k.option(-2), Some(("eps_px".into(), "0.2".into())));
        let k = Knob::of(SDF, &pairs(&[("eps_abs", "0.01")])).expect("knob");
        assert_eq!(k.option(1), Some(("eps_abs".into(), "0.005".into())));
    }

    #[test]
    fn mesh_knob_follows_the_tessellation_the_user_chose() {
        let k = Knob::of(MESH, &[]).expect("knob");
        assert_eq!(k.option(1), Some(("tess_px".into(), "0.125".into())));
        let k = Knob::of(MESH, &pairs(&[("preset", "fast")])).expect("knob");
        assert_eq!(k.option(0), Some(("tess_px".into(), "1".into())));
        let k = Knob::of(MESH, &pairs(&[("tess_level", "3")])).expect("knob");
        assert_eq!(k.option(2), Some(("tess_level".into(), "5".into())));
        assert_eq!(k.option(-9), Some(("tess_level".into(), "0".into())));
    }

    #[test]
    fn knob_specs_build_and_bad_options_are_errors() {
        assert_eq!(
            Knob::of(BackendId::REFERENCE, &[]).expect("knob"),
            Knob(None)
        );
        let err = Knob::of(SDF, &pairs(&[("nonsense", "1")])).unwrap_err();
        assert!(err.to_string().contains("nonsense"), "{err}");
        let k = Knob::of(SDF, &[]).expect("knob");
        let s = spec(SDF, &pairs(&[("max_steps", "64")]), &k, 1);
        assert_eq!(s.options.len(), 2);
        assert!(backend::check_options(&s).is_ok());
        assert_eq!(k.describe(1), "eps_px=0.025 q+1");
    }
}
