//! Estimates as the localizer reports them: per tag, the estimator's position with its
//! covariance, the samples behind it, a state, and when it was last updated.

use serde::Serialize;

use super::ingest::Ingest;
use super::relock::{self, Obs};

/// Position standard deviation (m) at or under which an estimate counts as converged.
pub const CONVERGED_SIGMA_M: f64 = 0.01;

/// How far an estimate has come.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum State {
    /// A position, not yet within [`CONVERGED_SIGMA_M`].
    Converging,
    /// A position within [`CONVERGED_SIGMA_M`] (one σ along its worse axis).
    Converged,
    /// Too little geometry for a position (too few phases, too short an aperture).
    InsufficientGeometry,
}

/// One tag's estimate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Estimate {
    /// EPC, upper-case hex.
    pub epc: String,
    /// Estimator name.
    pub estimator: &'static str,
    /// Position (m), when there is one.
    pub estimate: Option<[f64; 3]>,
    /// Covariance of the position, 3×3 row-major (m²); a 2D estimator's z row and column are 0
    /// (the height is assumed, not estimated).
    pub covariance: Option<[f64; 9]>,
    /// Phases the estimate rests on.
    pub samples: usize,
    /// How far it has come.
    pub state: State,
    /// Time of the newest phase (µs, the reads' clock).
    pub last_update_us: u64,
}

/// Phase ReLock in 2D for every tag of `ingest`, at tag height `z` with phase sign `sign`,
/// searching the side `facing` points to within `reach_m` (see [`relock::locate`]).
pub fn relock_all(
    ingest: &Ingest,
    z: f64,
    sign: f64,
    facing: [f64; 2],
    reach_m: f64,
) -> Vec<Estimate> {
    let mut by_tag: std::collections::BTreeMap<&str, (Vec<Obs>, u64)> = Default::default();
    for (key, series) in ingest.series() {
        let lambda = series.wavelength_m();
        let entry = by_tag.entry(key.2.as_str()).or_default();
        for seg in series.segments() {
            let segment = entry.0.last().map_or(0, |o| o.segment + 1);
            for s in seg {
                entry.1 = entry.1.max(s.t_us);
                entry.0.push(Obs {
                    phase_rad: s.phase_rad,
                    antenna: s.antenna,
                    wavelength_m: lambda,
                    segment,
                });
            }
        }
    }
    by_tag
        .into_iter()
        .map(|(epc, (obs, last))| {
            let base = Estimate {
                epc: epc.to_string(),
                estimator: "relock",
                estimate: None,
                covariance: None,
                samples: obs.len(),
                state: State::InsufficientGeometry,
                last_update_us: last,
            };
            match relock::locate(&obs, z, sign, facing, reach_m) {
                Ok(fix) => {
                    let [a, b, c, d] = fix.covariance;
                    let worse = a.max(d).max(0.0).sqrt();
                    Estimate {
                        estimate: Some(fix.position),
                        covariance: Some([a, b, 0.0, c, d, 0.0, 0.0, 0.0, 0.0]),
                        state: if worse <= CONVERGED_SIGMA_M {
                            State::Converged
                        } else {
                            State::Converging
                        },
                        ..base
                    }
                }
                Err(relock::NoFix::InsufficientGeometry) => base,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::localize::poses::Poses;
    use crate::localize::series::Ambiguity;
    use crate::reads::{AntennaPose, Read};

    fn read(epc: &str, t_us: u64, x: f64, tag: [f64; 2]) -> Read {
        let f = 865_700_000u64;
        let lambda = crate::localize::SPEED_OF_LIGHT / f as f64;
        let d = ((tag[0] - x).powi(2) + tag[1].powi(2)).sqrt();
        Read {
            epc: epc.into(),
            reader: Some("r".into()),
            antenna: 1,
            t_us,
            phase_rad: Some(
                (0.9 + 4.0 * std::f64::consts::PI * d / lambda).rem_euclid(std::f64::consts::TAU),
            ),
            rssi_dbm: None,
            channel_index: Some(1),
            channel_frequency_hz: Some(f),
            doppler_hz: None,
            antenna_pose: Some(AntennaPose {
                x,
                y: 0.0,
                z: 0.5,
                yaw_deg: 90.0,
                pitch_deg: 0.0,
            }),
            last_seen_us: None,
        }
    }

    #[test]
    fn every_tag_gets_an_estimate_or_says_why_not() {
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        // Tag A seen over 3 m of path, tag B in two reads only.
        for k in 0..300u64 {
            ingest.push(&read("AA", k * 10_000, -1.0 + 0.01 * k as f64, [0.5, 1.5]));
        }
        ingest.push(&read("BB", 0, 0.0, [1.0, 2.0]));
        ingest.push(&read("BB", 10_000, 0.01, [1.0, 2.0]));
        let all = relock_all(&ingest, 0.5, 1.0, [0.0, 1.0], 3.0);
        assert_eq!(all.len(), 2);
        let a = &all[0];
        assert_eq!(
            (a.epc.as_str(), a.estimator, a.samples),
            ("AA", "relock", 300)
        );
        let p = a.estimate.expect("a position");
        assert!((p[0] - 0.5).hypot(p[1] - 1.5) < 1e-3, "{p:?}");
        assert_eq!(a.state, State::Converged);
        assert_eq!(a.last_update_us, 2_990_000);
        let cov = a.covariance.expect("a covariance");
        assert_eq!(cov[8], 0.0, "the height is assumed");
        let b = &all[1];
        assert_eq!(b.state, State::InsufficientGeometry);
        assert_eq!((b.estimate, b.covariance, b.samples), (None, None, 2));
        // As JSON: the state in snake case, no NaN anywhere.
        let json = serde_json::to_string(&all).expect("serialises");
        assert!(
            json.contains("\"insufficient_geometry\"") && !json.contains("NaN"),
            "{json}"
        );
    }
}
