//! The statistics that need the geometry: the level's slope with distance, the off-axis drop,
//! the per-channel profiles, the level in front, and the phase against frequency and along
//! the aperture.

use super::*;

/// The statistics that need the geometry: slope, off-axis drop, per-channel profiles, level,
/// phase against frequency and along the aperture.
pub(super) fn geometry_stats(s: &mut Stats, summaries: &[Summary], layout: &Layout, freqs: &[u64]) {
    let (log_d, levels): (Vec<f64>, Vec<f64>) = summaries
        .iter()
        .map(|g| (distance(layout, g.park, g.tag).log2(), g.rssi_mean))
        .unzip();
    s.rssi_slope = line_fit(&log_d, &levels).map(|(_, b)| b);
    let band = |lo: f64, hi: f64| -> Vec<f64> {
        summaries
            .iter()
            .filter(|g| (lo..hi).contains(&off_axis(layout, g.park, g.tag)))
            .map(|g| g.rssi_mean)
            .collect()
    };
    if let (Some(off), Some(on)) = (mean(&band(30.0, 40.0)), mean(&band(0.0, 10.0))) {
        s.off_axis_drop = Some(off - on);
    }
    channel_stats(s, summaries, layout, freqs);
    front_stats(s, summaries, layout);
    aperture_stats(s, summaries, layout, freqs);
}

/// The distance (m) from park `park` to tag `tag`.
fn distance(layout: &Layout, park: usize, tag: usize) -> f64 {
    norm(sub(layout.tags[tag].1, layout.parks[park].at))
}

/// The angle (degrees) of tag `tag` off the boresight at park `park`.
fn off_axis(layout: &Layout, park: usize, tag: usize) -> f64 {
    let v = sub(layout.tags[tag].1, layout.parks[park].at);
    let b = layout.boresight;
    let c = (v[0] * b[0] + v[1] * b[1] + v[2] * b[2]) / norm(v);
    c.clamp(-1.0, 1.0).acos().to_degrees()
}

/// What the (park, tag) points with a group on every channel give, channel by channel.
struct Profiles {
    /// Each point's RSSI sigma across channels.
    channel_sigmas: Vec<f64>,
    /// Per channel: the sum of the points' mean-removed RSSI.
    profile_sum: Vec<f64>,
    /// Points summed in `profile_sum`.
    profile_n: usize,
    /// Each point's RMS residual of phase against frequency after a line fit.
    fit_residuals: Vec<f64>,
    /// Each point's spread of φ0 across channels.
    phi0_profiles: Vec<f64>,
    /// (park, channel) -> per-tag mean-removed φ0 profile value.
    phi0_by_channel: HashMap<(usize, usize), Vec<f64>>,
}

/// The per-channel statistics: RSSI across channels, band tilt, phase against frequency, φ0.
fn channel_stats(s: &mut Stats, summaries: &[Summary], layout: &Layout, freqs: &[u64]) {
    // Per (park, tag): the group means by channel, where every channel has a group.
    let n_ch = freqs.len();
    let mut by_point: HashMap<(usize, usize), Vec<Option<Summary>>> = HashMap::new();
    for g in summaries {
        by_point
            .entry((g.park, g.tag))
            .or_insert_with(|| vec![None; n_ch])[g.channel] = Some(*g);
    }
    let f_mhz: Vec<f64> = freqs.iter().map(|&f| f as f64 / 1e6).collect();
    let mut p = Profiles {
        channel_sigmas: Vec::new(),
        profile_sum: vec![0.0; n_ch],
        profile_n: 0,
        fit_residuals: Vec::new(),
        phi0_profiles: Vec::new(),
        phi0_by_channel: HashMap::new(),
    };
    let mut points: Vec<_> = by_point.keys().copied().collect();
    points.sort_unstable();
    for key in points {
        let row = &by_point[&key];
        let Some(full) = row.iter().copied().collect::<Option<Vec<Summary>>>() else {
            continue;
        };
        if n_ch < 2 {
            continue;
        }
        p.add(key, &full, layout, freqs, &f_mhz);
    }
    s.channel_rssi_sigma = quantile(&p.channel_sigmas, 0.5);
    if p.profile_n > 0 && n_ch > 1 {
        let profile: Vec<f64> = p
            .profile_sum
            .iter()
            .map(|x| x / p.profile_n as f64)
            .collect();
        let span = f_mhz[n_ch - 1] - f_mhz[0];
        s.band_tilt = line_fit(&f_mhz, &profile).map(|(_, b)| b * span);
    }
    s.channel_fit_residual = quantile(&p.fit_residuals, 0.5);
    s.phi0_profile = quantile(&p.phi0_profiles, 0.5);
    let spreads: Vec<f64> = p
        .phi0_by_channel
        .values()
        .filter(|v| v.len() == layout.tags.len() && v.len() > 1)
        .filter_map(|v| std(v))
        .collect();
    s.phi0_tag_spread = quantile(&spreads, 0.5);
}

impl Profiles {
    /// Adds point `key` (park, tag), whose groups `full` cover every channel.
    fn add(
        &mut self,
        key: (usize, usize),
        full: &[Summary],
        layout: &Layout,
        freqs: &[u64],
        f_mhz: &[f64],
    ) {
        let rssi: Vec<f64> = full.iter().map(|g| g.rssi_mean).collect();
        self.channel_sigmas.extend(std(&rssi));
        let m = mean(&rssi).unwrap_or(0.0);
        for (k, x) in rssi.iter().enumerate() {
            self.profile_sum[k] += x - m;
        }
        self.profile_n += 1;
        let mut phases: Vec<f64> = full.iter().map(|g| g.mode).collect();
        unwrap(&mut phases);
        if let Some((a, b)) = line_fit(f_mhz, &phases) {
            let res: Vec<f64> = f_mhz
                .iter()
                .zip(&phases)
                .map(|(f, p)| p - a - b * f)
                .collect();
            let rms = (res.iter().map(|r| r * r).sum::<f64>() / res.len() as f64).sqrt();
            self.fit_residuals.push(rms);
        }
        let d = distance(layout, key.0, key.1);
        let mut psi: Vec<f64> = full
            .iter()
            .zip(freqs)
            .map(|(g, &f)| g.mode - propagation(f as f64, d))
            .collect();
        unwrap(&mut psi);
        let pm = mean(&psi).unwrap_or(0.0);
        self.phi0_profiles.extend(population_std(&psi));
        for (k, p) in psi.iter().enumerate() {
            self.phi0_by_channel
                .entry((key.0, k))
                .or_default()
                .push(p - pm);
        }
    }
}

/// The level and the spread between tags, each tag seen from the park in front of it.
fn front_stats(s: &mut Stats, summaries: &[Summary], layout: &Layout) {
    // In front of each tag: the park nearest to it along the rail.
    let mut fronts = Vec::new();
    for tag in 0..layout.tags.len() {
        let Some(park) = (0..layout.parks.len())
            .min_by(|&a, &b| off_axis(layout, a, tag).total_cmp(&off_axis(layout, b, tag)))
        else {
            continue;
        };
        let here: Vec<f64> = summaries
            .iter()
            .filter(|g| g.park == park && g.tag == tag)
            .map(|g| g.rssi_mean)
            .collect();
        fronts.extend(mean(&here));
    }
    if fronts.len() == layout.tags.len() && !fronts.is_empty() {
        let max = fronts.iter().copied().fold(f64::MIN, f64::max);
        let min = fronts.iter().copied().fold(f64::MAX, f64::min);
        s.tag_spread = Some(max - min);
        s.level = mean(&fronts);
    }
}

/// Phase along the aperture against the nominal (and the fitted) geometry.
fn aperture_stats(s: &mut Stats, summaries: &[Summary], layout: &Layout, freqs: &[u64]) {
    // (tag, channel) -> (park, mode), parks in order.
    let mut series: HashMap<(usize, usize), Vec<(usize, f64)>> = HashMap::new();
    for g in summaries {
        series
            .entry((g.tag, g.channel))
            .or_default()
            .push((g.park, g.mode));
    }
    for v in series.values_mut() {
        v.sort_by_key(|&(p, _)| p);
    }
    let residual = |tag_at: [f64; 3], channel: usize, v: &[(usize, f64)]| -> Option<f64> {
        let f = freqs[channel] as f64;
        let mut r: Vec<f64> = v
            .iter()
            .map(|&(p, mode)| {
                let d = norm(sub(tag_at, layout.parks[p].at));
                wrap_pi(mode - propagation(f, d))
            })
            .collect();
        unwrap(&mut r);
        // RMS about the series' own mean: the constant offset removed.
        population_std(&r)
    };
    let mut nominal = Vec::new();
    let mut fitted = Vec::new();
    for (tag, (_, at)) in layout.tags.iter().enumerate() {
        let channels: Vec<(usize, &Vec<(usize, f64)>)> = (0..freqs.len())
            .filter_map(|c| series.get(&(tag, c)).map(|v| (c, v)))
            .filter(|(_, v)| v.len() >= 3)
            .collect();
        if channels.is_empty() {
            continue;
        }
        for &(c, v) in &channels {
            nominal.extend(residual(*at, c, v));
        }
        // The position within ±10 cm (x, y) that minimises the residual over every channel.
        let cost = |dx: f64, dy: f64| -> f64 {
            let p = [at[0] + dx, at[1] + dy, at[2]];
            channels
                .iter()
                .filter_map(|&(c, v)| residual(p, c, v))
                .map(|r| r * r)
                .sum::<f64>()
        };
        let mut best = (0.0, 0.0, cost(0.0, 0.0));
        // A 1 cm grid over the ±10 cm square, then 1 mm and 0.1 mm grids about the best.
        for step in [0.01, 0.001, 0.0001] {
            let (cx, cy) = (best.0, best.1);
            for i in -10..=10 {
                for j in -10..=10 {
                    let (dx, dy) = (cx + f64::from(i) * step, cy + f64::from(j) * step);
                    if dx.abs() > 0.1 + 1e-9 || dy.abs() > 0.1 + 1e-9 {
                        continue;
                    }
                    let c = cost(dx, dy);
                    if c < best.2 {
                        best = (dx, dy, c);
                    }
                }
            }
        }
        let p = [at[0] + best.0, at[1] + best.1, at[2]];
        for &(c, v) in &channels {
            fitted.extend(residual(p, c, v));
        }
    }
    s.aperture_nominal = mean(&nominal);
    s.aperture_fitted = mean(&fitted);
}
