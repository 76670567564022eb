//! The statistics of `../shared/research/real-reads.md`, computed from reads of a parked
//! aperture (one antenna parked at points along a line, tags at known nominal places).
//!
//! A *group* is one (park, tag, channel) with at least [`MIN_GROUP`] reads; its phase is the
//! circular mean of its main mode (the reads within π/2 of the circular mean of all).

use std::collections::HashMap;
use std::f64::consts::{PI, TAU};

use crate::physics::phase::SPEED_OF_LIGHT;
use crate::reads::Read;

/// Fewest reads a group needs to count.
pub const MIN_GROUP: usize = 5;

/// One stop of the antenna: parked at `at` from `from_us` to `to_us` (the reads' µs).
#[derive(Clone, Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Park {
    /// Start of the stop (µs).
    pub from_us: u64,
    /// End of the stop (µs).
    pub to_us: u64,
    /// Antenna position (m).
    pub at: [f64; 3],
}

/// What the statistics need to know of the measurement besides its reads (as JSON:
/// `{"parks": [{"from_us", "to_us", "at"}], "tags": [["EPC", [x, y, z]]], "boresight"}`).
#[derive(Clone, Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layout {
    /// The antenna's stops, in time order.
    pub parks: Vec<Park>,
    /// Each tag's EPC (upper-case hex) and nominal position (m).
    pub tags: Vec<(String, [f64; 3])>,
    /// The antenna's boresight (unit vector).
    pub boresight: [f64; 3],
}

/// The statistics of one measurement; `None` where the reads do not allow one.
#[derive(Clone, Debug, Default)]
pub struct Stats {
    /// Median over groups of the phase's circular std (rad).
    pub phase_sigma_median: Option<f64>,
    /// 90th percentile of the same (rad).
    pub phase_sigma_p90: Option<f64>,
    /// Exponent k of σ ∝ 10^(k·(ref − RSSI)/20), fitted over groups.
    pub phase_noise_exponent: Option<f64>,
    /// The fitted σ at −42 dBm (rad).
    pub phase_sigma_at_42: Option<f64>,
    /// The fitted σ at −57 dBm (rad).
    pub phase_sigma_at_57: Option<f64>,
    /// Share of reads about π from their group's mode.
    pub pi_flips: Option<f64>,
    /// Median over groups of the RSSI std (dB).
    pub rssi_sigma_median: Option<f64>,
    /// 90th percentile of the same (dB).
    pub rssi_sigma_p90: Option<f64>,
    /// Smallest step between two reported RSSI values (dB).
    pub rssi_step: Option<f64>,
    /// Slope of group-mean RSSI against log2(distance), whole aperture (dB per doubling).
    pub rssi_slope: Option<f64>,
    /// Mean RSSI with the tag 30–40° off boresight minus 0–10° (dB).
    pub off_axis_drop: Option<f64>,
    /// Median over (park, tag) of the std over channels of the group-mean RSSI (dB).
    pub channel_rssi_sigma: Option<f64>,
    /// Linear change across the band of the per-channel RSSI profile common to all tags (dB).
    pub band_tilt: Option<f64>,
    /// Max − min over tags of the mean RSSI with the antenna in front of each (dB).
    pub tag_spread: Option<f64>,
    /// Mean over tags of that RSSI (dBm).
    pub level: Option<f64>,
    /// Median over (park, tag) of the RMS residual of a free linear fit of phase against
    /// frequency (rad).
    pub channel_fit_residual: Option<f64>,
    /// Median over (park, tag) of the std over channels of φ − 4πfd/c, its mean removed (rad).
    pub phi0_profile: Option<f64>,
    /// Median over (park, channel) of the std across tags of that profile (rad).
    pub phi0_tag_spread: Option<f64>,
    /// Mean over (tag, channel) of the RMS of phase along the aperture against
    /// 4πd(x)/λ + const with the nominal geometry (rad).
    pub aperture_nominal: Option<f64>,
    /// The same with each tag's position fitted within ±10 cm (rad).
    pub aperture_fitted: Option<f64>,
    /// Excess kurtosis of the phase about each group's mode (pooled, each group standardised).
    pub phase_kurtosis: Option<f64>,
    /// Share of reads more than 5 robust σ from their group's mode.
    pub phase_outliers: Option<f64>,
    /// Share of reads more than 2 dB from their group's median RSSI.
    pub rssi_outliers: Option<f64>,
    /// Reads of the most read tag over reads of the least read one.
    pub reads_ratio: Option<f64>,
    /// Largest k such that every reported phase is a multiple of k·2π/4096.
    pub phase_quantum: Option<f64>,
    /// Share of gaps between two reads of a tag (counted in other tags' reads at the same
    /// park) of 5 or more.
    pub long_gaps: Option<f64>,
    /// Groups counted.
    pub groups: usize,
    /// Reads counted (those during a park, of a listed tag, with phase, RSSI and frequency).
    pub reads: usize,
}

struct Group {
    phases: Vec<f64>,
    rssi: Vec<f64>,
}

/// One group's summary.
#[derive(Clone, Copy)]
struct Summary {
    park: usize,
    tag: usize,
    channel: usize,
    mode: f64,
    sigma: f64,
    rssi_mean: f64,
}

/// Wraps an angle into (−π, π].
fn wrap_pi(x: f64) -> f64 {
    let y = (x + PI).rem_euclid(TAU) - PI;
    if y <= -PI {
        y + TAU
    } else {
        y
    }
}

fn circular_mean(xs: &[f64]) -> (f64, f64) {
    let (s, c) = xs
        .iter()
        .fold((0.0, 0.0), |(s, c), x| (s + x.sin(), c + x.cos()));
    let n = xs.len().max(1) as f64;
    (s.atan2(c), (s * s + c * c).sqrt() / n)
}

fn mean(xs: &[f64]) -> Option<f64> {
    (!xs.is_empty()).then(|| xs.iter().sum::<f64>() / xs.len() as f64)
}

fn std(xs: &[f64]) -> Option<f64> {
    let m = mean(xs)?;
    (xs.len() > 1)
        .then(|| (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (xs.len() - 1) as f64).sqrt())
}

fn population_std(xs: &[f64]) -> Option<f64> {
    let m = mean(xs)?;
    Some((xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / xs.len() as f64).sqrt())
}

/// The `q` quantile (0..1) by nearest rank; `None` for no values.
pub fn quantile(xs: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * q).round() as usize;
    Some(v[i.min(v.len() - 1)])
}

/// Least-squares line y = a + b·x: (a, b); `None` with fewer than two distinct x.
pub fn line_fit(xs: &[f64], ys: &[f64]) -> Option<(f64, f64)> {
    let (mx, my) = (mean(xs)?, mean(ys)?);
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let sxy: f64 = xs.iter().zip(ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let b = sxy / sxx;
    Some((my - b * mx, b))
}

/// Unwraps a sequence of angles in place: each step taken as its wrapped difference.
fn unwrap(xs: &mut [f64]) {
    for i in 1..xs.len() {
        xs[i] = xs[i - 1] + wrap_pi(xs[i] - xs[i - 1]);
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// Round-trip phase 4πfd/c (rad).
fn propagation(f_hz: f64, d: f64) -> f64 {
    4.0 * PI * f_hz * d / SPEED_OF_LIGHT
}

/// Computes every statistic of the reads of `layout`.
pub fn compute(reads: &[Read], layout: &Layout) -> Stats {
    let mut r = gather(reads, layout);
    let mut s = Stats {
        reads: r.counted,
        ..Stats::default()
    };
    let t = summarise(&r.groups);
    let summaries = &t.summaries;
    s.groups = summaries.len();
    if summaries.is_empty() {
        return s;
    }
    phase_noise_stats(&mut s, summaries);
    let total = t.total;
    s.pi_flips = Some(t.flips as f64 / total as f64);
    s.phase_outliers = Some(t.outliers as f64 / total as f64);
    s.rssi_outliers = Some(t.rssi_out as f64 / total as f64);
    s.rssi_sigma_median = quantile(&t.rssi_sigmas, 0.5);
    s.rssi_sigma_p90 = quantile(&t.rssi_sigmas, 0.9);
    s.phase_kurtosis = kurtosis(&t.pooled);
    r.rssi_values.sort_by(f64::total_cmp);
    s.rssi_step = r
        .rssi_values
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|&d| d > 1e-9)
        .min_by(f64::total_cmp);
    s.phase_quantum = (r.codes_gcd > 0).then_some(r.codes_gcd as f64);
    let (most, least) = (r.per_tag.iter().max(), r.per_tag.iter().min());
    if let (Some(&m), Some(&l)) = (most, least) {
        s.reads_ratio = (l > 0).then(|| m as f64 / l as f64);
    }
    s.long_gaps = long_gaps(&mut r.sequence, layout.tags.len());

    geometry_stats(&mut s, summaries, layout, &r.freqs);
    s
}

/// The reads that count (known tag, at a park, with phase, RSSI and channel), grouped.
struct Gathered {
    /// The channels' frequencies (Hz), ascending; a channel is its index.
    freqs: Vec<u64>,
    /// Phases and RSSI by (park, tag, channel).
    groups: HashMap<(usize, usize, usize), Group>,
    /// Reads per tag.
    per_tag: Vec<usize>,
    /// (park, time, tag) of each read.
    sequence: Vec<(usize, u64, usize)>,
    /// The GCD of the phase codes (of 4096 per turn).
    codes_gcd: u64,
    /// Every read's RSSI.
    rssi_values: Vec<f64>,
    /// Reads that count.
    counted: usize,
}

/// Sorts the reads of `layout` into groups and tallies, skipping those that do not count.
fn gather(reads: &[Read], layout: &Layout) -> Gathered {
    let epcs: HashMap<&str, usize> = layout
        .tags
        .iter()
        .enumerate()
        .map(|(i, (e, _))| (e.as_str(), i))
        .collect();
    let mut freqs: Vec<u64> = reads
        .iter()
        .filter_map(|r| r.channel_frequency_hz)
        .collect();
    freqs.sort_unstable();
    freqs.dedup();
    let channel_of: HashMap<u64, usize> = freqs.iter().enumerate().map(|(i, &f)| (f, i)).collect();
    let park_of = |t: u64| {
        let i = layout.parks.partition_point(|p| p.from_us <= t);
        i.checked_sub(1).filter(|&i| t <= layout.parks[i].to_us)
    };

    let mut groups: HashMap<(usize, usize, usize), Group> = HashMap::new();
    let mut per_tag = vec![0usize; layout.tags.len()];
    let mut sequence: Vec<(usize, u64, usize)> = Vec::new();
    let mut codes_gcd = 0u64;
    let mut rssi_values: Vec<f64> = Vec::new();
    let mut counted = 0;
    for r in reads {
        let (Some(&tag), Some(park)) = (epcs.get(r.epc.as_str()), park_of(r.t_us)) else {
            continue;
        };
        let (Some(phase), Some(rssi), Some(f)) = (r.phase_rad, r.rssi_dbm, r.channel_frequency_hz)
        else {
            continue;
        };
        let channel = channel_of[&f];
        counted += 1;
        per_tag[tag] += 1;
        sequence.push((park, r.t_us, tag));
        let code = (phase / TAU * 4096.0).round() as u64 % 4096;
        codes_gcd = gcd(codes_gcd, code);
        rssi_values.push(rssi);
        let g = groups.entry((park, tag, channel)).or_insert(Group {
            phases: Vec::new(),
            rssi: Vec::new(),
        });
        g.phases.push(phase);
        g.rssi.push(rssi);
    }
    Gathered {
        freqs,
        groups,
        per_tag,
        sequence,
        codes_gcd,
        rssi_values,
        counted,
    }
}

/// The groups' summaries and the counts pooled over the groups.
#[derive(Default)]
struct Tallies {
    /// One summary per group big enough, in key order.
    summaries: Vec<Summary>,
    /// Reads half a turn off their group's mode.
    flips: usize,
    /// Reads more than five robust sigmas off their group's mode.
    outliers: usize,
    /// Reads more than 2 dB off their group's median RSSI.
    rssi_out: usize,
    /// Reads in the summarised groups.
    total: usize,
    /// Main-lobe phase deviations in units of their group's sigma.
    pooled: Vec<f64>,
    /// Each group's RSSI sigma.
    rssi_sigmas: Vec<f64>,
}

/// Summarises each group (in key order) with enough reads, pooling the counts.
fn summarise(groups: &HashMap<(usize, usize, usize), Group>) -> Tallies {
    let mut t = Tallies::default();
    let mut keys: Vec<_> = groups.keys().copied().collect();
    keys.sort_unstable();
    for key in keys {
        t.add(key, &groups[&key]);
    }
    t
}

impl Tallies {
    /// Adds group `g` at `key` (park, tag, channel), unless it has too few main-lobe reads.
    fn add(&mut self, key: (usize, usize, usize), g: &Group) {
        if g.phases.len() < MIN_GROUP {
            return;
        }
        let (all_mean, _) = circular_mean(&g.phases);
        let main: Vec<f64> = g
            .phases
            .iter()
            .copied()
            .filter(|p| wrap_pi(p - all_mean).abs() < PI / 2.0)
            .collect();
        if main.len() < MIN_GROUP {
            return;
        }
        let (mode, r) = circular_mean(&main);
        let sigma = (-2.0 * r.min(1.0).ln()).max(0.0).sqrt();
        let devs: Vec<f64> = g.phases.iter().map(|p| wrap_pi(p - mode)).collect();
        self.flips += devs.iter().filter(|d| d.abs() > 0.75 * PI).count();
        let abs: Vec<f64> = devs.iter().map(|d| d.abs()).collect();
        let robust = 1.4826 * quantile(&abs, 0.5).unwrap_or(0.0);
        // A quantised group can have a zero MAD: count against one phase step then.
        let robust = robust.max(TAU / 4096.0);
        self.outliers += abs.iter().filter(|&&d| d > 5.0 * robust).count();
        let main_devs: Vec<f64> = devs
            .iter()
            .copied()
            .filter(|d| d.abs() < PI / 2.0)
            .collect();
        if let Some(sd) = population_std(&main_devs).filter(|&sd| sd > 0.0) {
            self.pooled.extend(main_devs.iter().map(|d| d / sd));
        }
        let median_rssi = quantile(&g.rssi, 0.5).unwrap_or(0.0);
        self.rssi_out += g
            .rssi
            .iter()
            .filter(|&&x| (x - median_rssi).abs() > 2.0)
            .count();
        self.total += g.phases.len();
        if let Some(sd) = std(&g.rssi) {
            self.rssi_sigmas.push(sd);
        }
        self.summaries.push(Summary {
            park: key.0,
            tag: key.1,
            channel: key.2,
            mode,
            sigma,
            rssi_mean: mean(&g.rssi).unwrap_or(f64::NAN),
        });
    }
}

/// The phase sigma's quantiles and its fit against the RSSI level.
fn phase_noise_stats(s: &mut Stats, summaries: &[Summary]) {
    let sigmas: Vec<f64> = summaries.iter().map(|g| g.sigma).collect();
    s.phase_sigma_median = quantile(&sigmas, 0.5);
    s.phase_sigma_p90 = quantile(&sigmas, 0.9);
    let (levels, log_sigmas): (Vec<f64>, Vec<f64>) = summaries
        .iter()
        .filter(|g| g.sigma > 0.0)
        .map(|g| (g.rssi_mean, g.sigma.log10()))
        .unzip();
    if let Some((a, b)) = line_fit(&levels, &log_sigmas) {
        s.phase_noise_exponent = Some(-20.0 * b);
        s.phase_sigma_at_42 = Some(10f64.powf(a + b * -42.0));
        s.phase_sigma_at_57 = Some(10f64.powf(a + b * -57.0));
    }
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

/// Pooled excess kurtosis m4/m2² − 3.
fn kurtosis(xs: &[f64]) -> Option<f64> {
    let m = mean(xs)?;
    let m2 = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / xs.len() as f64;
    let m4 = xs.iter().map(|x| (x - m).powi(4)).sum::<f64>() / xs.len() as f64;
    (m2 > 0.0).then(|| m4 / (m2 * m2) - 3.0)
}

/// Share of gaps of 5 or more other-tag reads between two reads of one tag at one park.
fn long_gaps(sequence: &mut [(usize, u64, usize)], tags: usize) -> Option<f64> {
    sequence.sort_unstable();
    let (mut long, mut gaps) = (0usize, 0usize);
    let mut since = vec![None::<usize>; tags];
    let mut park = usize::MAX;
    for &(p, _, tag) in sequence.iter() {
        if p != park {
            park = p;
            since.iter_mut().for_each(|s| *s = None);
        }
        if let Some(n) = since[tag] {
            gaps += 1;
            if n >= 5 {
                long += 1;
            }
        }
        for (k, s) in since.iter_mut().enumerate() {
            if k == tag {
                *s = Some(0);
            } else if let Some(n) = s {
                *n += 1;
            }
        }
    }
    (gaps > 0).then(|| long as f64 / gaps as f64)
}

mod geometry;
use geometry::geometry_stats;

#[cfg(test)]
#[path = "stats_tests.rs"]
mod tests;
