//! Tests of the statistics on reads built to known answers.
use super::*;

fn read(epc: &str, t_us: u64, phase: f64, rssi: f64, f_hz: u64) -> Read {
    Read {
        epc: crate::reads::Epc::parse(epc).expect("hex"),
        reader: None,
        antenna: 1,
        t_us,
        phase_rad: Some(phase.rem_euclid(TAU)),
        rssi_dbm: Some(rssi),
        channel_index: None,
        channel_frequency_hz: Some(f_hz),
        doppler_hz: None,
        antenna_pose: None,
        last_seen_us: None,
    }
}

/// `n` parks of 0.9 s each second, `step` m apart along x.
fn parks(n: u64, step: f64) -> Vec<Park> {
    (0..n)
        .map(|i| Park {
            from_us: i * 1_000_000,
            to_us: i * 1_000_000 + 900_000,
            at: [i as f64 * step, 0.0, 0.0],
        })
        .collect()
}

/// An ideal aperture (phase exactly 4πfd/c plus per-channel constants, RSSI constant)
/// gives zero residuals and the delay it was built with.
#[test]
fn an_ideal_aperture_has_no_residual_and_its_own_delay() {
    let tags = vec![
        ("0A".to_string(), [0.3, 0.8, 0.0]),
        ("0B".to_string(), [0.6, 0.8, 0.0]),
    ];
    let parks = parks(20, 0.05);
    let freqs: Vec<u64> = (0..8).map(|k| 920_625_000 + k * 500_000).collect();
    let tau = 35e-9;
    let mut reads = Vec::new();
    for park in &parks {
        for (k, (epc, at)) in tags.iter().enumerate() {
            let d = norm(sub(*at, park.at));
            for (c, &f) in freqs.iter().enumerate() {
                let phase = propagation(f as f64, d) + 4.0 * PI * f as f64 * tau + k as f64;
                for n in 0..6u64 {
                    let t = park.from_us + (c as u64 * 6 + n) * 1000 + k as u64 * 100;
                    reads.push(read(epc, t, phase, -50.0 - k as f64, f));
                }
            }
        }
    }
    let layout = Layout {
        parks,
        tags,
        boresight: [0.0, 1.0, 0.0],
    };
    let s = compute(&reads, &layout);
    assert!(s.aperture_nominal.expect("aperture") < 1e-3, "{s:?}");
    assert!(s.aperture_fitted.expect("fitted") < 1e-3);
    assert!(s.channel_fit_residual.expect("fit") < 1e-3);
    let profile = s.phi0_profile.expect("profile");
    let want = 4.0
        * PI
        * tau
        * population_std(&freqs.iter().map(|&f| f as f64).collect::<Vec<_>>()).expect("std");
    assert!((profile - want).abs() < 1e-3, "{profile} {want}");
    assert!(s.phi0_tag_spread.expect("spread") < 1e-3);
    assert_eq!(s.tag_spread, Some(1.0));
    assert_eq!(s.rssi_sigma_median, Some(0.0));
    assert_eq!(s.pi_flips, Some(0.0));
}

/// A tag placed 3 cm off its nominal place shows in the nominal residual, not once its
/// position is fitted.
#[test]
fn a_misplaced_tag_is_found_by_the_fit() {
    let nominal = [0.5, 0.7, 0.0];
    let truth = [0.53, 0.69, 0.0];
    let parks = parks(50, 0.02);
    let f = 922_000_000u64;
    let mut reads = Vec::new();
    for park in &parks {
        let d = norm(sub(truth, park.at));
        for n in 0..5 {
            reads.push(read(
                "0A",
                park.from_us + n,
                propagation(f as f64, d),
                -50.0,
                f,
            ));
        }
    }
    let layout = Layout {
        parks,
        tags: vec![("0A".to_string(), nominal)],
        boresight: [0.0, 1.0, 0.0],
    };
    let s = compute(&reads, &layout);
    assert!(s.aperture_nominal.expect("nominal") > 0.3, "{s:?}");
    assert!(s.aperture_fitted.expect("fitted") < 0.01, "{s:?}");
}

#[test]
fn gaps_and_kurtosis() {
    let mut seq: Vec<(usize, u64, usize)> = vec![(0, 0, 0), (0, 1, 1), (0, 2, 0)];
    seq.extend((3..9).map(|t| (0, t, 1)));
    seq.push((0, 9, 0));
    // Tag 0: gaps 1 and 6; tag 1: gaps 1 (over tag 0's read) and 0 ×5, then none.
    let g = long_gaps(&mut seq, 2).expect("gaps");
    assert!((g - 1.0 / 8.0).abs() < 1e-12, "{g}");
    let normal: Vec<f64> = (1..2000)
        .map(|i| {
            // Inverse-CDF samples of a standard normal by a logistic approximation are
            // close enough that the kurtosis is near 0 and far from a uniform's −1.2.
            let u = i as f64 / 2000.0;
            (u / (1.0 - u)).ln() / 1.702
        })
        .collect();
    let k = kurtosis(&normal).expect("kurtosis");
    assert!(k > -0.6 && k < 1.5, "{k}");
    let uniform: Vec<f64> = (0..1000).map(|i| i as f64).collect();
    assert!((kurtosis(&uniform).expect("k") + 1.2).abs() < 0.01);
}
