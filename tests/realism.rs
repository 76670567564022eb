//! The simulated reader's measurements look like an Impinj reader's, seen over loopback with
//! the project's client, with the built-in defaults and with the `impinj-r420` reader model:
//! consecutive same-channel reads of a tag differ by well under 1 dB
//! (docs/simulator.md, "Measurement model"), a static tag's RSSI, phase and Doppler scatter
//! with the documented σ, weaker reads are noisier, and \[G\] eq. 5 (`gazebo_eq5`) still gives
//! the old, distance-growing RSSI noise.

mod common;

use std::collections::HashMap;
use std::f64::consts::TAU;

use common::*;
use llrp_gateway::net::clock::Speed;
use llrp_gateway::physics::noise::weak_signal_scale_with;
use llrp_gateway::scenario::{RssiModel, Scenario};

/// One read as the client decodes it.
#[derive(Clone, Copy, Debug)]
struct Seen {
    tag: u8,
    channel: u16,
    t_us: u64,
    rssi_dbm: f64,
    phase_rad: f64,
    doppler_hz: f64,
}

/// Inventories every antenna of `scenario` at `--speed max` with a report per read and the
/// Impinj RSSI, phase and Doppler, until `n` reads.
async fn reads(scenario: &Scenario, n: usize) -> Vec<Seen> {
    let sim = start(scenario, Speed::Max).await;
    let mut c = connect(&sim).await;
    c.enable_impinj_extensions(T).await.expect("extensions");
    let spec = rospec(
        1,
        vec![0],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
    );
    c.add_rospec(spec, T).await.expect("ADD_ROSPEC");
    c.enable_rospec(1, T).await.expect("ENABLE_ROSPEC");
    let (tags, _) = collect_reports(&mut c, T * 6, |t| t.len() >= n).await;
    sim.shutdown().await;
    assert!(tags.len() >= n, "only {} reads", tags.len());
    tags.iter()
        .map(|t| Seen {
            tag: *t.epc_bytes().last().expect("an EPC"),
            channel: t.channel_index.map_or(0, |c| c.0),
            t_us: t.first_seen_timestamp_utc.map_or(0, |u| u.0),
            rssi_dbm: f64::from(t.impinj_peak_rssi().expect("ImpinjPeakRSSI")) / 100.0,
            phase_rad: f64::from(t.impinj_phase_angle().expect("phase")) * TAU / 4096.0,
            doppler_hz: f64::from(t.impinj_doppler().expect("Doppler")) / 16.0,
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty(), "no values");
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// |a − b| on the circle.
fn angle(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    d.min(TAU - d)
}

/// |ΔRSSI| of consecutive reads of one tag on one channel at most 50 ms apart (the
/// `impinj-r420` reader pauses 15 ms after each round: a tag among S1's few is read about every
/// 20–30 ms; the robot moves 2–3 cm in 50 ms).
fn consecutive_rssi_steps(seen: &[Seen]) -> Vec<f64> {
    let mut last: HashMap<(u8, u16), Seen> = HashMap::new();
    let mut steps = Vec::new();
    for s in seen {
        if let Some(p) = last.insert((s.tag, s.channel), *s) {
            if s.t_us.saturating_sub(p.t_us) <= 50_000 {
                steps.push((s.rssi_dbm - p.rssi_dbm).abs());
            }
        }
    }
    steps
}

/// S1 read as `model` reads (its own defaults without).
fn s1_as(model: Option<&str>) -> Scenario {
    let mut s = Scenario::default_s1_with(model).expect("S1 with a known model");
    for r in &mut s.readers {
        r.listen = "127.0.0.1:0".into();
    }
    s
}

#[tokio::test]
async fn default_scenario_rssi_steps_are_under_a_decibel() {
    rssi_steps_are_under_a_decibel(None).await;
}

/// The same with the `impinj-r420` reader model (its compression, per-channel response and
/// heavy tails leave consecutive reads as close).
#[tokio::test]
async fn impinj_r420_rssi_steps_are_under_a_decibel() {
    rssi_steps_are_under_a_decibel(Some("impinj-r420")).await;
}

async fn rssi_steps_are_under_a_decibel(model: Option<&str>) {
    let seen = reads(&s1_as(model), 3000).await;
    let steps = consecutive_rssi_steps(&seen);
    assert!(steps.len() > 1000, "{} pairs", steps.len());
    let m = median(steps.clone());
    assert!(m <= 1.0, "median |ΔRSSI| {m} dB");
    // Not noise-free either: a real reader's RSSI moves between reads.
    assert!(steps.iter().any(|&d| d > 0.0), "every pair identical");
    // Reported in Impinj's 0.5 dB steps.
    assert!(seen
        .iter()
        .all(|s| (s.rssi_dbm * 2.0 - (s.rssi_dbm * 2.0).round()).abs() < 1e-9));
}

#[tokio::test]
async fn default_scenario_phase_steps_are_about_the_documented_sigma() {
    phase_steps_are_about_the_models_sigma(None).await;
}

/// The same with the `impinj-r420` reader model: its noise law, Student's t of the same σ
/// (the median of |t₈|/σ is 0.61, of a Gaussian's 0.67), and its 10-bit quantum; its smooth
/// angle-dependent error and per-channel phase change too slowly to show over three reads.
#[tokio::test]
async fn impinj_r420_phase_steps_are_about_the_models_sigma() {
    phase_steps_are_about_the_models_sigma(Some("impinj-r420")).await;
}

async fn phase_steps_are_about_the_models_sigma(model: Option<&str>) {
    // The robot moves, so the phase of a tag drifts between reads; over three consecutive
    // same-channel reads a few ms apart that drift is linear in time, and what is left after
    // extrapolating from the first two is noise: σ·√(1 + (1 + r)² + r²), r the ratio of the
    // two gaps (at most 80 ms together: the reader pauses 15 ms after each round).
    let scenario = s1_as(model);
    let spec = scenario.readers[0].antennas[0].clone();
    let quantum = TAU / f64::from(1u32 << spec.phase_resolution_bits.min(12));
    let sigma_at = |rssi: f64| {
        let noise = spec.phase_noise_rad
            * weak_signal_scale_with(rssi, spec.phase_noise_ref_dbm, spec.noise_exponent);
        (noise.powi(2) + quantum.powi(2) / 12.0).sqrt()
    };
    let seen = reads(&scenario, 4000).await;
    let mut by_tag: HashMap<(u8, u16), Vec<Seen>> = HashMap::new();
    for s in &seen {
        by_tag.entry((s.tag, s.channel)).or_default().push(*s);
    }
    let mut ratios = Vec::new();
    for series in by_tag.values() {
        for w in series.windows(3) {
            let (g1, g2) = (w[1].t_us - w[0].t_us, w[2].t_us - w[1].t_us);
            if g1 == 0 || g2 == 0 || g1 + g2 > 80_000 {
                continue;
            }
            let r = g2 as f64 / g1 as f64;
            let step = (w[1].phase_rad - w[0].phase_rad + std::f64::consts::PI).rem_euclid(TAU)
                - std::f64::consts::PI;
            let predicted = w[1].phase_rad + step * r;
            let residual = angle(w[2].phase_rad, predicted);
            let s0 = sigma_at(w[0].rssi_dbm);
            let s1 = sigma_at(w[1].rssi_dbm);
            let s2 = sigma_at(w[2].rssi_dbm);
            let expected = (s2.powi(2) + ((1.0 + r) * s1).powi(2) + (r * s0).powi(2)).sqrt();
            ratios.push(residual / expected);
        }
    }
    assert!(ratios.len() > 500, "{} triples", ratios.len());
    // For Gaussian noise the median of |x|/σ is 0.674.
    let m = median(ratios);
    assert!(
        (0.674 * 0.75..0.674 * 1.3).contains(&m),
        "median residual {m} σ"
    );
}

#[tokio::test]
async fn gazebo_eq5_keeps_the_distance_growing_noise() {
    let mut s = s1();
    for a in &mut s.readers[0].antennas {
        a.rssi_model = RssiModel::GazeboEq5;
        a.rssi_noise = Some(0.01);
    }
    let steps = consecutive_rssi_steps(&reads(&s, 3000).await);
    assert!(steps.len() > 1000, "{} pairs", steps.len());
    let m = median(steps);
    // [G] eq. 5 at S1's 1.6–3.5 m from the path: several dB between consecutive reads.
    assert!(m >= 2.0, "median |ΔRSSI| {m} dB");
}

/// Tags at 1.5, 3 and 5 m on the boresight of a fixed antenna, on one channel, with every
/// measurement default of the reader model `model` (the built-in ones without).
fn static_scenario(model: Option<&str>) -> Scenario {
    let json = r#"{
      "name": "static",
      "seed": 11,
      "world": { "min": [-2, -2, 0], "max": [10, 2, 3] },
      "tags": [
        { "epc": "E20000000000000000000001", "position": [1.5, 0, 1] },
        { "epc": "E20000000000000000000002", "position": [3.0, 0.3, 1] },
        { "epc": "E20000000000000000000003", "position": [5.0, -0.3, 1] }
      ],
      "readers": [{
        "name": "r", "listen": "127.0.0.1:0", "region": "fcc", "fixed_channel": 7,
        "antennas": [{ "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } } }]
      }]
    }"#;
    Scenario::from_json_with(json, std::path::Path::new("."), model)
        .expect("static scenario is valid")
}

#[tokio::test]
async fn static_tags_scatter_with_the_documented_sigmas() {
    static_tags_scatter_as_the_model_says(None).await;
}

/// The same with the `impinj-r420` reader model: its noise law (0.011 rad at −42 dBm, growing
/// as 10^(0.75·Δ/20)), heavy tails of the same σ, and its 10-bit phase.
#[tokio::test]
async fn static_tags_scatter_as_the_impinj_r420_model_says() {
    static_tags_scatter_as_the_model_says(Some("impinj-r420")).await;
}

async fn static_tags_scatter_as_the_model_says(model: Option<&str>) {
    let scenario = static_scenario(model);
    let spec = scenario.readers[0].antennas[0].clone();
    let seen = reads(&scenario, 3000).await;
    let t0 = seen.first().map_or(0, |s| s.t_us);
    let mut phase_sigmas = Vec::new();
    for tag in 1..=3u8 {
        // Three simulated seconds of the tag (about 40 reads a second each with the reader's
        // pause after every round).
        let mine: Vec<&Seen> = seen
            .iter()
            .filter(|s| s.tag == tag && s.t_us < t0 + 3_000_000)
            .collect();
        assert!(mine.len() >= 50, "tag {tag}: {} reads", mine.len());
        let n = mine.len() as f64;
        let mean = mine.iter().map(|s| s.rssi_dbm).sum::<f64>() / n;
        let var = mine
            .iter()
            .map(|s| (s.rssi_dbm - mean).powi(2))
            .sum::<f64>()
            / n;
        let scale = weak_signal_scale_with(mean, spec.phase_noise_ref_dbm, spec.noise_exponent);
        let sd = var.sqrt();
        if spec.rssi_sigma_grows {
            // A σ well under the 0.5 dB step: what the step leaves depends on where the level
            // falls between two steps; at most the step's own spread and the noise's.
            let most = (spec.rssi_sigma_db * scale).max(0.25) + 0.05;
            assert!(
                sd <= most,
                "tag {tag}: RSSI σ {sd:.3} dB, at most {most:.3}"
            );
        } else {
            // σ of the noise plus the 0.5 dB step's own (step²/12), with room for the estimate.
            let expected = (spec.rssi_sigma_db.powi(2) + 0.25 / 12.0).sqrt();
            assert!(
                sd > 0.7 * expected && sd < 1.3 * expected,
                "tag {tag}: RSSI σ {sd:.3} dB, expected {expected:.3}"
            );
        }
        // Phase: circular spread about the mean, against the documented σ at this level.
        let (c, s) = mine.iter().fold((0.0, 0.0), |(c, s), r| {
            (c + r.phase_rad.cos(), s + r.phase_rad.sin())
        });
        let centre = s.atan2(c);
        let phase_sd = (mine
            .iter()
            .map(|r| angle(r.phase_rad, centre).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        let sigma = spec.phase_noise_rad * scale;
        // The phase quantum q (2π/4096 in the 12-bit field, 2π/1024 at 10 bits) adds q²/12.
        let quantum = TAU / f64::from(1u32 << spec.phase_resolution_bits.min(12));
        let sigma = (sigma.powi(2) + quantum.powi(2) / 12.0).sqrt();
        assert!(
            phase_sd > 0.75 * sigma && phase_sd < 1.25 * sigma,
            "tag {tag} at {mean:.1} dBm: phase σ {phase_sd:.4} rad, expected {sigma:.4}"
        );
        phase_sigmas.push(phase_sd);
        // Doppler of a static tag: centred on 0, never exactly 0 throughout.
        let dopplers: Vec<f64> = mine.iter().map(|r| r.doppler_hz).collect();
        let d_mean = dopplers.iter().sum::<f64>() / n;
        let d_sd = (dopplers.iter().map(|d| (d - d_mean).powi(2)).sum::<f64>() / n).sqrt();
        let d_sigma = spec.doppler_sigma_hz * scale;
        assert!(
            d_sd > 0.75 * d_sigma && d_sd < 1.25 * d_sigma,
            "tag {tag}: Doppler σ {d_sd:.2} Hz, expected {d_sigma:.2}"
        );
        assert!(d_mean.abs() < 4.0 * d_sigma / n.sqrt() + 0.1, "{d_mean}");
    }
    // The far tag is noisier than the near one.
    assert!(phase_sigmas[2] > 1.5 * phase_sigmas[0], "{phase_sigmas:?}");
}
