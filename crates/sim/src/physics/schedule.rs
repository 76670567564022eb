//! How likely a reply is to be decoded near the edge of the read zone.

/// Midpoint of the success probability, in dB of forward-link margin above the tag's
/// sensitivity.
pub const EDGE_MARGIN_DB: f64 = 1.0;
/// Width of the logistic fall-off, in dB.
pub const EDGE_WIDTH_DB: f64 = 0.5;

/// Probability that an attempt on a tag powered `margin_db` above its sensitivity succeeds:
/// 0 below the sensitivity, then logistic in the margin (½ at 1 dB, 0.98 at 3 dB).
pub fn read_probability(margin_db: f64) -> f64 {
    if margin_db.is_nan() || margin_db < 0.0 {
        return 0.0;
    }
    let p = 1.0 / (1.0 + (-(margin_db - EDGE_MARGIN_DB) / EDGE_WIDTH_DB).exp());
    if p.is_finite() {
        p
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edge_probability_falls_off() {
        assert_eq!(read_probability(-0.1), 0.0);
        assert_eq!(read_probability(f64::NEG_INFINITY), 0.0);
        assert!((read_probability(EDGE_MARGIN_DB) - 0.5).abs() < 1e-12);
        assert!(read_probability(3.0) > 0.97);
        assert!(read_probability(20.0) > 0.999_999);
        assert!(read_probability(0.5) < read_probability(1.5));
    }
}
