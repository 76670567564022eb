//! `bench readrate`: the simulated reader's read rate against the number of tags in the field,
//! per RF mode, through its own LLRP output, printed beside the published measurements of
//! Impinj readers (docs/measurement.md "Read rate against population") and drawn with them.

use std::path::Path;

use plotters::prelude::*;

use super::bench::{simulate_with, Inventory};
use crate::scenario::Scenario;

/// Tag counts the curve is measured at.
pub const POPULATIONS: [usize; 11] = [1, 2, 3, 6, 11, 16, 21, 40, 64, 128, 300];

/// RF modes the curve is measured in (ModeIdentifier), with their names.
pub const MODES: [(u16, &str); 4] = [
    (0, "mode 0 (FM0, 640 kHz)"),
    (1, "mode 1 (Miller 2, 640 kHz)"),
    (2, "mode 2 (Miller 4, 274 kHz)"),
    (1000, "mode 1000 (AutoSet: Miller 4, 250 kHz)"),
];

/// A published measurement: tags in the field, reads/s in all, and where and how it was made.
pub struct Published {
    /// Tags in the field.
    pub tags: usize,
    /// Reads (or tags) per second, all tags together.
    pub reads_per_s: f64,
    /// Reader, conditions and source.
    pub source: &'static str,
}

/// The measurements found (docs/measurement.md gives each one's source in full). Where a
/// source gives one tag's rate among others, the total is that rate times the tags (ours:
/// every tag read alike).
pub const PUBLISHED: [Published; 12] = [
    Published {
        tags: 1,
        reads_per_s: 63.0,
        source: "R420, 16 channels, mode not stated (Tagwatch, CoNEXT '17, §3.2: 63 Hz a tag)",
    },
    Published {
        tags: 40,
        reads_per_s: 480.0,
        source: "R420, as above, \"near 40\" tags (12 Hz a tag)",
    },
    Published {
        tags: 3,
        reads_per_s: 156.6,
        source: "R420, one antenna, 922 MHz, \"high-performance mode\" (Tagbeat, MobiCom '16: \
                 1,565 reads of one tag in 30 s)",
    },
    Published {
        tags: 6,
        reads_per_s: 315.4,
        source: "R420, as above (1,577 in 30 s)",
    },
    Published {
        tags: 11,
        reads_per_s: 388.7,
        source: "R420, as above (1,060 in 30 s)",
    },
    Published {
        tags: 16,
        reads_per_s: 592.0,
        source: "R420, as above (1,110 in 30 s)",
    },
    Published {
        tags: 21,
        reads_per_s: 728.0,
        source: "R420, as above (1,040 in 30 s)",
    },
    Published {
        tags: 1,
        reads_per_s: 69.0,
        source: "R420 with sllurp, an AISpec per tag (crozenboom/RFID-Locate-main Test11-2)",
    },
    Published {
        tags: 15,
        reads_per_s: 125.0,
        source: "R420 with sllurp, an AISpec per 4 tags (same data set, Test10-2; median)",
    },
    Published {
        tags: 5,
        reads_per_s: 140.0,
        source: "a Speedway with sllurp, settings not stated (sllurp issue #23)",
    },
    Published {
        tags: 1,
        reads_per_s: 130.0,
        source: "Indy RS500 module, population estimate 1 (manual, Table 5-12)",
    },
    Published {
        tags: 16,
        reads_per_s: 50.0,
        source: "Indy RS500 module, estimate 16 (manual, Table 5-12)",
    },
];

/// `n` static tags on a grid 2–3.2 m before one fixed antenna (FCC hopping), read as
/// `reader_model` reads.
pub fn field(n: usize, reader_model: &str) -> Result<Scenario, String> {
    let tags: Vec<serde_json::Value> = (0..n)
        .map(|i| {
            serde_json::json!({
                "epc": format!("E2000000000000000000{i:04X}"),
                "position": [
                    2.0 + (i % 3) as f64 * 0.6,
                    -1.0 + ((i / 3) % 5) as f64 * 0.5,
                    0.6 + (i / 15) as f64 * 0.02,
                ],
            })
        })
        .collect();
    let v = serde_json::json!({
        "name": format!("field-{n}"), "seed": 4, "reader_model": reader_model,
        "world": { "min": [-2, -5, 0], "max": [10, 5, 3] },
        "tags": tags,
        "readers": [{ "name": "r", "listen": "127.0.0.1:0", "region": "fcc",
            "antennas": [{ "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } },
                           "beamwidth_deg": 120 }] }]
    });
    Scenario::from_json(&v.to_string()).map_err(|e| e.to_string())
}

/// Reads per second, all tags together, of `n` tags read for `seconds` in RF mode `mode` by
/// one antenna with a continuous AISpec and a report per read (the project's own client).
pub fn rate(n: usize, mode: u16, reader_model: &str, seconds: f64) -> Result<f64, String> {
    let s = field(n, reader_model)?;
    let inventory = Inventory {
        mode: Some(mode),
        session: None,
    };
    let run = simulate_with(&s, seconds, inventory);
    Ok(run.reads.len() as f64 / seconds)
}

/// Draws the curves (one per mode of [`MODES`]) and the [`PUBLISHED`] points to `path`.
pub fn plot(path: &Path, curves: &[Vec<(usize, f64)>]) -> Result<(), String> {
    let text = super::plot::font();
    let top = curves.iter().flatten().map(|p| p.1).fold(200.0, f64::max) * 1.1;
    let root = BitMapBackend::new(path, (1000, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(20);
    if text {
        builder
            .caption("Read rate against tags in the field", ("sans-serif", 22))
            .x_label_area_size(40)
            .y_label_area_size(60);
    }
    let mut chart = builder
        .build_cartesian_2d((0.8f64..400.0).log_scale(), 0.0..top)
        .map_err(|e| e.to_string())?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("tags in the field").y_desc("reads/s, all tags");
    } else {
        mesh.disable_x_axis().disable_y_axis();
    }
    mesh.draw().map_err(|e| e.to_string())?;
    let colors = [BLUE, MAGENTA, RED, GREEN];
    for ((points, (_, name)), color) in curves.iter().zip(MODES).zip(colors) {
        let line: Vec<(f64, f64)> = points.iter().map(|&(n, r)| (n as f64, r)).collect();
        let series = chart
            .draw_series(LineSeries::new(line.iter().copied(), color.stroke_width(2)))
            .map_err(|e| e.to_string())?;
        if text {
            series
                .label(format!("simulated, {name}"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
    }
    let series = chart
        .draw_series(
            PUBLISHED
                .iter()
                .map(|p| Cross::new((p.tags as f64, p.reads_per_s), 7, BLACK.stroke_width(2))),
        )
        .map_err(|e| e.to_string())?;
    if text {
        series
            .label("published (R420: Tagwatch, Tagbeat, sllurp; RS500 module)")
            .legend(|(x, y)| Cross::new((x + 10, y), 6, BLACK.stroke_width(2)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ideal_rate_falls_from_one_tag_to_many_and_a_faster_mode_reads_more() {
        let one = rate(1, 1000, "ideal", 2.0).expect("runs");
        let many = rate(64, 1000, "ideal", 2.0).expect("runs");
        let fast = rate(64, 0, "ideal", 2.0).expect("runs");
        // The air interface alone, rounds back to back: one tag a round against framed
        // ALOHA's share of the slots, the total falls by about a tenth (docs/measurement.md
        // "The population curve").
        assert!(
            many < one && many > 0.7 * one,
            "1 tag {one}/s, 64 tags {many}/s"
        );
        assert!(fast > 3.0 * many, "mode 0 {fast}/s, mode 1000 {many}/s");
    }

    #[test]
    fn the_impinj_r420_model_reads_as_the_published_r420s() {
        // Mode 0 (Max Throughput) against Tagwatch's lone tag and Tagbeat's "high-performance
        // mode": each tag's rate within a fifth of theirs, and the total rising with the tags
        // (the reader's pause after each round shared among more reads), as theirs does.
        let per_tag = |n: usize| rate(n, 0, "impinj-r420", 4.0).expect("runs") / n as f64;
        for (n, published) in [(1, 63.0), (6, 52.6), (16, 37.0), (21, 34.7)] {
            let ours = per_tag(n);
            assert!(
                (ours / published - 1.0).abs() < 0.2,
                "{n} tags: {ours:.1} a tag a second, published {published}"
            );
        }
        let ideal = rate(1, 0, "ideal", 2.0).expect("runs");
        assert!(ideal > 10.0 * per_tag(1), "back to back: {ideal}/s");
    }

    #[test]
    fn an_unknown_reader_model_is_named_with_the_known_ones() {
        let e = rate(1, MODES[0].0, "acme-9000", 1.0).expect_err("refused");
        assert!(e.contains("acme-9000") && e.contains("impinj-r420"), "{e}");
    }
}
