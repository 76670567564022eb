//! Tests of an antenna the reader never leaves: its rounds run on ([`super::Model::chained_rounds`]).

use crate::physics::tests::fixed_scenario;
use crate::physics::{gen2, Model, Want};

/// Three tags before an antenna that is its AISpec's only one, and the reads of `[t0, t1)`.
fn lone_antenna_reads(alone: bool, t0_us: u64, t1_us: u64) -> Vec<(u64, usize)> {
    let tags = [[2.0, -0.3, 1.0], [2.2, 0.0, 1.0], [2.0, 0.3, 1.0]];
    let m = Model::new(&fixed_scenario(&tags, serde_json::json!({})), 0);
    let air = gen2::Air {
        anchor_us: alone.then_some(0),
        ..Default::default()
    };
    let want = Want {
        phase: true,
        doppler: false,
    };
    m.inventory_with(1, t0_us, t1_us, None, None, want, &air)
        .iter()
        .map(|r| (r.time_us, r.tag))
        .collect()
}

/// Share of the reads after which a tag's next read comes 5 or more reads of others later.
fn long_gaps(reads: &[(u64, usize)]) -> f64 {
    let mut last: [Option<usize>; 3] = [None; 3];
    let (mut gaps, mut long) = (0usize, 0usize);
    for (k, &(_, tag)) in reads.iter().enumerate() {
        if let Some(j) = last[tag] {
            gaps += 1;
            long += usize::from(k - j > 5);
        }
        last[tag] = Some(k);
    }
    long as f64 / gaps.max(1) as f64
}

#[test]
fn an_antenna_the_reader_never_leaves_reads_every_tag_once_a_round() {
    let alone = lone_antenna_reads(true, 0, 10_000_000);
    let rotating = lone_antenna_reads(false, 0, 10_000_000);
    // Rounds run on across epochs: a tag waits at most for the rest of its round and the
    // next one (4 reads of the others), except where a block's end cuts a round.
    assert!(long_gaps(&alone) < 0.01, "{}", long_gaps(&alone));
    // Cut at every 25 ms epoch's end, as when the reader moves to the next antenna.
    assert!(long_gaps(&rotating) > 0.02, "{}", long_gaps(&rotating));
    let per_tag = |tag| alone.iter().filter(|r| r.1 == tag).count() as f64;
    let (most, least) = (
        per_tag(0).max(per_tag(1)).max(per_tag(2)),
        per_tag(0).min(per_tag(1)).min(per_tag(2)),
    );
    assert!(most / least < 1.02, "{most} / {least}");
    // No time is lost to the epochs: more reads than when every epoch cuts its last round.
    assert!(
        alone.len() > rotating.len(),
        "{} vs {}",
        alone.len(),
        rotating.len()
    );
}

#[test]
fn a_lone_antennas_window_split_anywhere_gives_the_same_reads() {
    let whole = lone_antenna_reads(true, 0, 1_000_000);
    // Cuts inside a block, on an epoch's edge and on a block's edge.
    let mut split = Vec::new();
    let cuts = [0, 137_777, 250_000, 400_000, 612_345, 1_000_000];
    for w in cuts.windows(2) {
        split.extend(lone_antenna_reads(true, w[0], w[1]));
    }
    assert_eq!(whole, split);
    assert!(whole.len() > 100, "{}", whole.len());
}

/// The reads per tag of 40 tags before one antenna over 2 s, with the rounds among `select`'s
/// tags only when given.
fn crowd_reads(select: Option<&gen2::Selected>, alone: bool) -> Vec<usize> {
    let tags: Vec<[f64; 3]> = (0..40)
        .map(|k| [1.5 + 0.01 * f64::from(k), -0.4 + 0.02 * f64::from(k), 1.0])
        .collect();
    let m = Model::new(&fixed_scenario(&tags, serde_json::json!({})), 0);
    let air = gen2::Air {
        anchor_us: alone.then_some(0),
        select: select.map(|s| std::sync::Arc::new(s.clone())),
        ..Default::default()
    };
    let mut per_tag = vec![0; tags.len()];
    for r in m.inventory_with(1, 0, 2_000_000, None, None, Want::ALL, &air) {
        per_tag[r.tag] += 1;
    }
    per_tag
}

#[test]
fn tags_the_selects_leave_out_never_answer_and_the_others_get_their_slots() {
    let chosen = gen2::Selected::from_fn(40, |t| t % 10 == 3);
    for alone in [false, true] {
        let all = crowd_reads(None, alone);
        let some = crowd_reads(Some(&chosen), alone);
        assert!(all.iter().all(|&n| n > 0), "every tag is read: {all:?}");
        for tag in 0..40 {
            if chosen.contains(tag) {
                // Four tags share the rounds instead of forty: several times the reads.
                assert!(
                    some[tag] > 3 * all[tag],
                    "tag {tag}: {} vs {}",
                    some[tag],
                    all[tag]
                );
            } else {
                assert_eq!(some[tag], 0, "tag {tag} was left out");
            }
        }
    }
}
