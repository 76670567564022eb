//! The parked-rail replica of a real Impinj measurement (`fixtures/scenarios/rail/`) through
//! the simulated reader's own LLRP output: with the `impinj-r420` reader model its reads'
//! statistics fall inside the real reads' tolerance bands (docs/measurement.md "Validation");
//! with the `ideal` model they do not.

use std::path::Path;

use llrp_gateway::realism::{real::FIGURES, run_setup};

const RAIL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/scenarios/rail");

/// Figures the Gen2 scheduler does not yet reproduce (docs/measurement.md "Where the model
/// still differs"): each 25 ms epoch's last round is cut, so a tag is sometimes skipped.
const KNOWN_MISSES: [&str; 2] = [
    "reads per tag, most / least",
    "read-order gaps of 5 or more (share)",
];

#[test]
fn the_impinj_r420_model_reads_like_the_real_reader_at_0_88_and_0_51_m() {
    for d in [0.88, 0.51] {
        let o = run_setup(Path::new(RAIL), d, Some("impinj-r420")).expect("rail scenario runs");
        let unexpected: Vec<_> = o
            .outside
            .iter()
            .filter(|n| !KNOWN_MISSES.contains(n))
            .collect();
        assert!(
            unexpected.is_empty(),
            "{d} m: outside the real reads' bands: {unexpected:?}\n{:?}",
            o.stats
        );
        assert!(o.stats.groups >= 1000, "{d} m: {} groups", o.stats.groups);
    }
}

#[test]
fn the_ideal_model_reads_far_cleaner_than_the_real_reader() {
    let o = run_setup(Path::new(RAIL), 0.88, Some("ideal")).expect("rail scenario runs");
    assert!(
        o.outside.len() >= FIGURES.len() / 2,
        "only {} of {} outside: {:?}",
        o.outside.len(),
        FIGURES.len(),
        o.outside
    );
    for name in [
        "aperture residual, fitted (rad)",
        "level in front of the tags (dBm)",
    ] {
        assert!(o.outside.contains(&name), "{name} inside: {:?}", o.stats);
    }
}
