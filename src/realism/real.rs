//! The real figures of `../shared/research/real-reads.md` (an Impinj reader, the parked rail
//! at 0.88, 0.68 and 0.51 m) and the band each simulated figure must fall in.

use super::stats::Stats;

/// The three tag distances of the real measurement (m).
pub const DISTANCES: [f64; 3] = [0.88, 0.68, 0.51];

/// How a simulated figure is judged against the real ones.
#[derive(Clone, Copy, Debug)]
pub enum Band {
    /// Within a factor of 1.5 of the real figure at the same distance (or of the one figure
    /// given for all three).
    Ratio([f64; 3]),
    /// Inside [lo, hi]: the real figures vary across the setups by more than 1.5× (their range
    /// widened by 1.5× on each side), or the notes give a band, or the figure is a count.
    Within(f64, f64),
    /// Within ± the given amount of the real figure at the same distance (absolute levels).
    Plus([f64; 3], f64),
}

/// One statistic: its name, how the real reads show it, and its band.
pub struct Figure {
    /// Name as the notes give it.
    pub name: &'static str,
    /// The real figure(s) as the notes print them.
    pub real: &'static str,
    /// The band a simulated value must fall in.
    pub band: Band,
    /// The statistic's value in a [`Stats`].
    pub get: fn(&Stats) -> Option<f64>,
}

/// Widened by 1.5× on each side: the band for figures that differ across the setups.
const fn widened(lo: f64, hi: f64) -> Band {
    Band::Within(lo / 1.5, hi * 1.5)
}

/// Every statistic of the notes, in their order (the phase σ against level as two figures,
/// the phase quantum and the read order from the notes' classifier section).
pub const FIGURES: [Figure; 26] = [
    Figure {
        name: "phase σ median (rad)",
        real: "0.015 / 0.014 / 0.014",
        band: Band::Ratio([0.015, 0.014, 0.014]),
        get: |s| s.phase_sigma_median,
    },
    Figure {
        name: "phase σ p90 (rad)",
        real: "0.029 / 0.027 / 0.028",
        band: Band::Ratio([0.029, 0.027, 0.028]),
        get: |s| s.phase_sigma_p90,
    },
    Figure {
        name: "phase-noise exponent k",
        real: "0.46 / 0.91 / 0.80",
        band: widened(0.46, 0.91),
        get: |s| s.phase_noise_exponent,
    },
    Figure {
        name: "phase σ at −42 dBm (rad)",
        real: "0.011",
        band: Band::Ratio([0.011; 3]),
        get: |s| s.phase_sigma_at_42,
    },
    Figure {
        name: "phase σ at −57 dBm (rad)",
        real: "0.040",
        band: Band::Ratio([0.040; 3]),
        get: |s| s.phase_sigma_at_57,
    },
    Figure {
        name: "π flips (share of reads)",
        real: "none",
        band: Band::Within(0.0, 0.0005),
        get: |s| s.pi_flips,
    },
    Figure {
        name: "RSSI σ median (dB)",
        real: "0.13",
        band: Band::Ratio([0.13; 3]),
        get: |s| s.rssi_sigma_median,
    },
    Figure {
        name: "RSSI σ p90 (dB)",
        real: "0.25",
        band: Band::Ratio([0.25; 3]),
        get: |s| s.rssi_sigma_p90,
    },
    Figure {
        name: "RSSI step (dB)",
        real: "0.5",
        band: Band::Ratio([0.5; 3]),
        get: |s| s.rssi_step,
    },
    Figure {
        name: "RSSI slope (dB per doubling)",
        real: "−8.4 / −5.1 / −11.6",
        band: Band::Within(-11.6 * 1.5, -5.1 / 1.5),
        get: |s| s.rssi_slope,
    },
    Figure {
        name: "off-axis drop 30–40° (dB)",
        real: "−2.3 / −0.3 / −1.6",
        band: Band::Within(-2.3 * 1.5, -0.3 / 1.5),
        get: |s| s.off_axis_drop,
    },
    Figure {
        name: "per-channel RSSI σ (dB)",
        real: "0.27–0.30",
        band: widened(0.27, 0.30),
        get: |s| s.channel_rssi_sigma,
    },
    Figure {
        name: "band tilt over 3.5 MHz (dB)",
        real: "+0.58 to +0.64",
        band: widened(0.58, 0.64),
        get: |s| s.band_tilt,
    },
    Figure {
        name: "tag spread (dB)",
        real: "4.3 / 5.0 / 4.8",
        band: Band::Ratio([4.3, 5.0, 4.8]),
        get: |s| s.tag_spread,
    },
    Figure {
        name: "level in front of the tags (dBm)",
        real: "−46.9 / −46.3 / −43.8",
        band: Band::Plus([-46.9, -46.3, -43.8], 3.0),
        get: |s| s.level,
    },
    Figure {
        name: "phase across channels: fit residual (rad)",
        real: "0.010–0.011",
        band: widened(0.010, 0.011),
        get: |s| s.channel_fit_residual,
    },
    Figure {
        name: "φ0 profile over channels (rad)",
        real: "0.50",
        band: Band::Ratio([0.50; 3]),
        get: |s| s.phi0_profile,
    },
    Figure {
        name: "φ0 spread across tags (rad)",
        real: "0.02",
        band: Band::Ratio([0.02; 3]),
        get: |s| s.phi0_tag_spread,
    },
    Figure {
        name: "aperture residual, nominal (rad)",
        real: "0.34 / 0.45 / 0.53",
        band: Band::Ratio([0.34, 0.45, 0.53]),
        get: |s| s.aperture_nominal,
    },
    Figure {
        name: "aperture residual, fitted (rad)",
        real: "0.19 / 0.26 / 0.32",
        band: Band::Ratio([0.19, 0.26, 0.32]),
        get: |s| s.aperture_fitted,
    },
    Figure {
        name: "phase excess kurtosis",
        real: "3.0 / 2.3 / 3.5",
        band: widened(2.3, 3.5),
        get: |s| s.phase_kurtosis,
    },
    Figure {
        name: "phase outliers > 5 robust σ (share)",
        real: "0.15–0.23 %",
        band: widened(0.0015, 0.0023),
        get: |s| s.phase_outliers,
    },
    Figure {
        name: "RSSI outliers > 2 dB (share)",
        real: "0.03–0.07 %",
        band: widened(0.0003, 0.0007),
        get: |s| s.rssi_outliers,
    },
    Figure {
        name: "reads per tag, most / least",
        real: "1.00",
        band: Band::Within(1.0, 1.05),
        get: |s| s.reads_ratio,
    },
    Figure {
        name: "phase quantum (× 2π/4096)",
        real: "4",
        band: Band::Within(4.0, 4.0),
        get: |s| s.phase_quantum,
    },
    Figure {
        name: "read-order gaps of 5 or more (share)",
        real: "none",
        band: Band::Within(0.0, 0.01),
        get: |s| s.long_gaps,
    },
];

impl Band {
    /// Whether `value`, measured at the setup of index `setup` in [`DISTANCES`], is inside.
    pub fn holds(&self, value: f64, setup: usize) -> bool {
        let eps = 1e-9;
        match *self {
            Band::Ratio(real) => {
                let r = real[setup.min(2)];
                let q = value / r;
                q >= 1.0 / 1.5 - eps && q <= 1.5 + eps
            }
            Band::Within(lo, hi) => value >= lo - eps && value <= hi + eps,
            Band::Plus(real, d) => (value - real[setup.min(2)]).abs() <= d + eps,
        }
    }

    /// The band as text for the setup of index `setup`.
    pub fn describe(&self, setup: usize) -> String {
        match *self {
            Band::Ratio(real) => {
                let r = real[setup.min(2)];
                format!("{} .. {}", short(r / 1.5), short(r * 1.5))
            }
            Band::Within(lo, hi) => format!("{} .. {}", short(lo), short(hi)),
            Band::Plus(real, d) => {
                let r = real[setup.min(2)];
                format!("{} .. {}", short(r - d), short(r + d))
            }
        }
    }
}

/// A number in four significant digits at most.
pub fn short(x: f64) -> String {
    if x == 0.0 {
        "0".to_string()
    } else if x.abs() >= 100.0 {
        format!("{x:.1}")
    } else if x.abs() >= 1.0 {
        format!("{x:.2}")
    } else if x.abs() >= 0.01 {
        format!("{x:.3}")
    } else {
        format!("{x:.5}")
    }
}
