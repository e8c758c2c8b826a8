//! The JSON metadata section: provenance, bake parameters, timings, units.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::rgb9e5::{RGB9E5_MAX_RELATIVE_ERROR, RGB9E5_NAME};

/// Program that produced an archive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Generator {
    /// Program name, e.g. `"prm-bake"`.
    pub name: String,
    /// Program version, e.g. `"0.1.0"`.
    pub version: String,
}

/// Units of the quantities stored in the archive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Units {
    /// Unit of entry positions and of the source scene, e.g. `"m"`.
    pub length: String,
    /// Unit of texel values, e.g. `"W/m^2"` or `"relative"`.
    pub irradiance: String,
}

impl Default for Units {
    fn default() -> Self {
        Units {
            length: "m".into(),
            irradiance: "relative".into(),
        }
    }
}

/// Contents of the metadata section (a UTF-8 JSON object).
///
/// Unknown keys in a file are ignored, so later minor versions may add keys.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metadata {
    /// Program that wrote the archive.
    pub generator: Generator,
    /// Bake parameters, free-form.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Random seed of the bake.
    pub seed: u64,
    /// Wall-clock seconds per bake phase.
    pub timings: BTreeMap<String, f64>,
    /// Units of positions and texel values.
    pub units: Units,
    /// Path of the source scene relative to the archive's directory, with
    /// `/` separators.
    pub source_scene: String,
    /// Fingerprint of the source scene; stored as 16 hex digits.
    #[serde(with = "hex_u64")]
    pub scene_fingerprint: u64,
    /// Texel encoding name: `"rgb9e5ufloat"`, the encoding of the emitters' lightmaps and of
    /// the panes a GPU run time uploads (set by the writer).
    pub texel_encoding: String,
    /// Relative error bound of the largest channel of a texel (set by the
    /// writer: `2^-9` for RGB9E5).
    pub texel_relative_error_bound: f64,
    /// The bake's estimate of its own accuracy (optional; absent from the JSON when `None`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<Accuracy>,
}

/// The bake's estimate of its own accuracy (metadata key `accuracy`): the archive's
/// indirect light, blended as the player blends it, against a reference path tracer at a sample
/// of exit points, for a few point lights the bake placed itself (formats/prm.md §3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Accuracy {
    /// Exit points compared (one drawn at random from each of as many equal runs of the atlas's
    /// exit points).
    pub exit_points: u32,
    /// Reference paths per exit point and light.
    pub paths: u32,
    /// Clusters kept per frame in the estimate (the archive's `top_k`).
    pub top_k: u32,
    /// Residual groups whose summed panes carried the dropped clusters' light in the estimate
    /// ([`crate::residual_groups`]; 0: the kept clusters were scaled up instead).
    pub residual_groups: u32,
    /// One record per test light.
    pub lights: Vec<LightAccuracy>,
}

/// One test light of an [`Accuracy`] estimate. Errors are relative L2 over the exit points and
/// the three channels, `‖PRM − ref‖ / ‖ref‖`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LightAccuracy {
    /// Where the point light was.
    pub position: [f32; 3],
    /// The error with the reference's own noise `Σ var` removed from both sums,
    /// `√(max(0, Σ|PRM − ref|² − Σ var) / (Σ|ref|² − Σ var))` (formats/prm.md §3.1).
    pub error: f64,
    /// The error as measured, the reference's noise included.
    pub measured: f64,
    /// The reference's own noise, `√Σ variance / ‖ref‖`.
    pub reference_noise: f64,
    /// Energy, `Σ PRM / Σ ref` over the exit points and channels.
    pub energy: f64,
    /// [`LightAccuracy::error`] with every cluster blended (K = all, no truncation).
    pub error_all_clusters: f64,
    /// Standard error of [`LightAccuracy::error`] over draws of the exit points and the
    /// reference's paths.
    pub standard_error: f64,
}

impl Accuracy {
    /// Mean of the lights' errors (noise removed); 0 without lights.
    pub fn mean_error(&self) -> f64 {
        mean(self.lights.iter().map(|l| l.error))
    }

    /// Mean of the lights' errors with every cluster blended.
    pub fn mean_error_all_clusters(&self) -> f64 {
        mean(self.lights.iter().map(|l| l.error_all_clusters))
    }

    /// Mean of the lights' energies; 0 without lights.
    pub fn mean_energy(&self) -> f64 {
        mean(self.lights.iter().map(|l| l.energy))
    }

    /// Standard error of [`Accuracy::mean_error`] (the lights' combined in quadrature).
    pub fn mean_standard_error(&self) -> f64 {
        let n = self.lights.len();
        if n == 0 {
            return 0.0;
        }
        self.lights.iter().map(|l| l.standard_error.powi(2)).sum::<f64>().sqrt() / n as f64
    }

    /// Mean of the reference's noise over the lights.
    pub fn mean_reference_noise(&self) -> f64 {
        mean(self.lights.iter().map(|l| l.reference_noise))
    }

    /// Checks what §3.1 requires (every number finite, all but positions ≥ 0); a reader refuses
    /// an archive whose estimate breaks it, so a writer should drop such an estimate.
    pub fn validate(&self) -> Result<(), String> {
        for (i, l) in self.lights.iter().enumerate() {
            let values = [
                l.error,
                l.measured,
                l.reference_noise,
                l.energy,
                l.error_all_clusters,
                l.standard_error,
            ];
            if !values.iter().all(|v| v.is_finite() && *v >= 0.0) || !l.position.iter().all(|p| p.is_finite()) {
                return Err(format!("accuracy of light {i} is not finite and non-negative: {l:?}"));
            }
        }
        Ok(())
    }
}

fn mean(values: impl ExactSizeIterator<Item = f64>) -> f64 {
    let n = values.len();
    if n == 0 {
        0.0
    } else {
        values.sum::<f64>() / n as f64
    }
}

impl Metadata {
    /// Metadata with the given generator and empty/zero everything else.
    pub fn new(generator_name: impl Into<String>, generator_version: impl Into<String>) -> Self {
        Metadata {
            generator: Generator {
                name: generator_name.into(),
                version: generator_version.into(),
            },
            params: serde_json::Map::new(),
            seed: 0,
            timings: BTreeMap::new(),
            units: Units::default(),
            source_scene: String::new(),
            scene_fingerprint: 0,
            texel_encoding: RGB9E5_NAME.into(),
            texel_relative_error_bound: RGB9E5_MAX_RELATIVE_ERROR,
            accuracy: None,
        }
    }

    /// Checks what JSON cannot express or the format forbids.
    pub(crate) fn validate(&self) -> Result<(), String> {
        for (k, v) in &self.timings {
            if !v.is_finite() {
                return Err(format!("timing {k:?} is not finite"));
            }
        }
        if !self.texel_relative_error_bound.is_finite() {
            return Err("texel_relative_error_bound is not finite".into());
        }
        if self.texel_encoding != RGB9E5_NAME {
            return Err(format!(
                "texel_encoding is {:?}, the format has only {RGB9E5_NAME:?}",
                self.texel_encoding
            ));
        }
        if let Some(a) = &self.accuracy {
            a.validate()?;
        }
        Ok(())
    }
}

/// Serde adapter writing a `u64` as exactly 16 lowercase hex digits.
mod hex_u64 {
    use serde::{de::Error, Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &u64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&format!("{v:016x}"))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
        let s = String::deserialize(d)?;
        if s.len() != 16 || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(D::Error::custom(format!(
                "scene_fingerprint must be 16 hex digits, got {s:?}"
            )));
        }
        u64::from_str_radix(&s, 16).map_err(D::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accuracy_is_optional_and_round_trips() {
        let mut m = Metadata::new("test", "1.2.3");
        let s = serde_json::to_string(&m).unwrap();
        assert!(!s.contains("accuracy"), "{s}");
        assert_eq!(serde_json::from_str::<Metadata>(&s).unwrap().accuracy, None);
        let light = |error: f64| LightAccuracy {
            position: [0.0, 1.0, 0.0],
            error,
            measured: 0.12,
            reference_noise: 0.05,
            energy: 0.97,
            error_all_clusters: 0.08,
            standard_error: 0.01,
        };
        m.accuracy = Some(Accuracy {
            exit_points: 256,
            paths: 256,
            top_k: 32,
            residual_groups: 4,
            lights: vec![light(0.1), light(0.2)],
        });
        let s = serde_json::to_string(&m).unwrap();
        let back: Metadata = serde_json::from_str(&s).unwrap();
        assert_eq!(back, m);
        let a = back.accuracy.unwrap();
        assert!((a.mean_error() - 0.15).abs() < 1e-12);
        assert!((a.mean_energy() - 0.97).abs() < 1e-12);
        assert!(m.validate().is_ok());
        m.accuracy.as_mut().unwrap().lights[1].energy = f64::NAN;
        assert!(m.validate().unwrap_err().contains("light 1"));
    }

    #[test]
    fn json_round_trip_and_hex_fingerprint() {
        let mut m = Metadata::new("test", "1.2.3");
        m.scene_fingerprint = 0x00ab_cdef_0123_4567;
        m.timings.insert("trace".into(), 1.5);
        m.params.insert("bounces".into(), 3.into());
        let s = serde_json::to_string(&m).unwrap();
        assert!(s.contains("\"scene_fingerprint\":\"00abcdef01234567\""), "{s}");
        let back: Metadata = serde_json::from_str(&s).unwrap();
        assert_eq!(back, m);
        let bad = s.replace("00abcdef01234567", "0xabcdef01234567");
        assert!(serde_json::from_str::<Metadata>(&bad).is_err());
        let upper = s.replace("00abcdef01234567", "00ABCDEF01234567");
        assert_eq!(
            serde_json::from_str::<Metadata>(&upper).unwrap().scene_fingerprint,
            m.scene_fingerprint
        );
    }

    #[test]
    fn validate_rejects_non_finite_timings() {
        let mut m = Metadata::new("t", "0");
        assert!(m.validate().is_ok());
        m.timings.insert("x".into(), f64::NAN);
        assert!(m.validate().is_err());
    }
}
