//! The amplitude gain of an antenna's lobe tabulated over the direction cosine, with the
//! bounds the field tests take from it.

use super::SLACK_REL;
use crate::physics::antenna::Lobe;

/// Steps of the gain table over the direction cosine in [−1, 1].
const TABLE_STEPS: usize = 2048;

/// Amplitude gain √(boresight × pattern) of a lobe tabulated over the direction cosine, for
/// bounds: it never decreases with the cosine.
#[derive(Clone, Debug)]
pub(in crate::physics) struct GainTable(Box<[f64; TABLE_STEPS + 1]>);

impl GainTable {
    /// The table of `lobe`.
    pub(in crate::physics) fn new(lobe: &Lobe) -> GainTable {
        let mut table = Box::new([0.0; TABLE_STEPS + 1]);
        for (i, g) in table.iter_mut().enumerate() {
            *g = lobe
                .gain_cos(-1.0 + 2.0 * i as f64 / TABLE_STEPS as f64)
                .sqrt();
        }
        GainTable(table)
    }

    /// Position of cosine `c` in the table, clamped to it (NaN gives 0).
    fn index(c: f64) -> f64 {
        ((c + 1.0) * 0.5 * TABLE_STEPS as f64).clamp(0.0, TABLE_STEPS as f64)
    }

    /// At least the amplitude gain at any direction cosine ≤ `c`.
    pub(super) fn above(&self, c: f64) -> f64 {
        let x = if c.is_nan() {
            TABLE_STEPS as f64
        } else {
            Self::index(c)
        };
        // 0 ≤ x ≤ TABLE_STEPS: truncation is floor (through i64, a single instruction); the
        // next entry is at least the one at ⌈x⌉ (the table never decreases), without testing
        // whether x is whole.
        let i = x as i64 as usize + 1;
        self.0[i.min(TABLE_STEPS)] * (1.0 + SLACK_REL)
    }

    /// At most the amplitude gain at any direction cosine ≥ `c`.
    pub(super) fn below(&self, c: f64) -> f64 {
        // 0 ≤ index ≤ TABLE_STEPS (NaN gives 0): truncation through i64 is floor.
        let i = Self::index(c) as i64 as usize;
        self.0[i.min(TABLE_STEPS)] * (1.0 - SLACK_REL)
    }
}
