//! What every estimator takes and gives: an unwrapped phase with where the antenna was
//! ([`Obs`]), a 2D or 3D position with its covariance ([`Fix`], [`Fix3`]), and why there is
//! none ([`NoFix`]).

/// One unwrapped phase with where the antenna was.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Obs {
    /// Unwrapped phase (rad).
    pub phase_rad: f64,
    /// Antenna position (m).
    pub antenna: [f64; 3],
    /// Channel wavelength (m).
    pub wavelength_m: f64,
    /// Segment the phase belongs to (its own offset), 0-based.
    pub segment: usize,
    /// Group of segments whose offsets are equal modulo `period_rad` (one series), 0-based.
    pub group: usize,
    /// Group of series whose offsets are equal modulo `period_rad` once calibrated (the
    /// calibrated antennas of one reader on one channel; see [`crate::calibrate`]), 0-based;
    /// as `group` for a series not calibrated.
    pub joint: usize,
    /// Period of the phase as reported (rad): 2π, or π with the π ambiguity.
    pub period_rad: f64,
    /// Reads the phase stands for: 1 for a read; more for a bin of neighbouring reads of one
    /// segment, whose phase and antenna position are the reads' means.
    pub weight: f64,
    /// A bin's reads' squared deviations from the line through their phases along the path
    /// (rad²): the phase noise its mean hides; 0 for a read.
    pub scatter_rad2: f64,
    /// When it was read (µs; a bin's: its reads' mean).
    pub t_us: u64,
}

/// A 2D estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct Fix {
    /// Position (m); z is the tag height assumed.
    pub position: [f64; 3],
    /// Covariance of (x, y), m², row-major 2×2.
    pub covariance: [f64; 4],
    /// Root-mean-square phase residual (rad).
    pub rms_rad: f64,
}

impl Fix {
    /// This fix as a [`Fix3`] whose covariance's z row and column are 0 (the height assumed).
    pub fn planar(self) -> Fix3 {
        let [a, b, c, d] = self.covariance;
        Fix3 {
            position: self.position,
            covariance: [a, b, 0.0, c, d, 0.0, 0.0, 0.0, 0.0],
            rms_rad: self.rms_rad,
        }
    }
}

/// Why no estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoFix {
    /// Too few phases, or an aperture too short to fix a position.
    InsufficientGeometry,
}

/// A 3D estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct Fix3 {
    /// Position (m).
    pub position: [f64; 3],
    /// Covariance of (x, y, z), m², row-major 3×3.
    pub covariance: [f64; 9],
    /// Root-mean-square phase residual (rad), over the phases behind it.
    pub rms_rad: f64,
}
