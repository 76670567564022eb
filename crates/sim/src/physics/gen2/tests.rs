//! Unit tests of the Gen2 timing and rounds against closed forms.

use super::*;
use crate::physics::seed;

fn tags(n: usize) -> Vec<usize> {
    (0..n).collect()
}

/// A channel where tag k's reply is at `levels[k]` dBm (−50 when not listed) and decodes
/// unless `deaf`; counts the replies asked about.
#[derive(Default)]
struct Fixed {
    levels: Vec<f64>,
    deaf: bool,
    asked: usize,
}

impl Radio for Fixed {
    fn level(&mut self, tag: usize, _t_us: f64) -> f64 {
        self.levels.get(tag).copied().unwrap_or(-50.0)
    }
    fn reply(&mut self, _tag: usize, _t_us: f64) -> bool {
        self.asked += 1;
        !self.deaf
    }
}

#[test]
fn mode_2_slot_times_follow_the_standard() {
    let t = RfMode::IMPINJ_MODE_2.slot_times(96);
    // Tari 20 µs, PIE 2: RTcal 60 µs, frame-sync 92.5 µs, reader bit 30 µs.
    let query_rep = 12.5 + 20.0 + 60.0 + 4.0 * 30.0;
    let tpri = 1e3 / 274.0;
    let rn16 = (10.0 + 16.0 + 1.0) * 4.0 * tpri;
    let epc = (10.0 + 128.0 + 1.0) * 4.0 * tpri;
    let ack = 92.5 + 18.0 * 30.0;
    let (t1, t2, t3) = (60.0, 10.0 * tpri, 60.0);
    assert!((t.empty_us - (query_rep + t1 + t3)).abs() < 1e-9);
    assert!((t.collided_us - (query_rep + t1 + rn16 + t2)).abs() < 1e-9);
    let success = query_rep + t1 + rn16 + t2 + ack + t1 + epc + t2;
    assert!((t.success_us - success).abs() < 1e-9);
    // About 3.5 ms a read, 0.33 ms an empty slot.
    assert!((3400.0..3500.0).contains(&t.success_us), "{}", t.success_us);
    let query = 12.5 + 20.0 + 60.0 + DIVIDE_RATIO / 274.0 * 1e3 + 22.0 * 30.0;
    assert!((t.query_extra_us - (query - query_rep)).abs() < 1e-9);
    // FM0 at 640 kHz is several times faster; a longer EPC takes longer.
    let fast = RfMode::IMPINJ_MODE_0.slot_times(96);
    assert!(fast.success_us * 3.0 < t.success_us, "{}", fast.success_us);
    assert!(RfMode::IMPINJ_MODE_2.slot_times(128).success_us > t.success_us);
}

#[test]
fn a_lone_tag_is_read_in_one_slot() {
    let times = RfMode::IMPINJ_MODE_2.slot_times(96);
    let mut rng = seed::stream(&[1]);
    let r = round(
        &mut rng,
        &times,
        &tags(1),
        0.0,
        f64::INFINITY,
        &mut Fixed::default(),
    );
    assert_eq!(r.reads.len(), 1);
    assert_eq!(r.slots, [0, 0, 1]);
    assert!((r.duration_us - (times.query_extra_us + times.success_us)).abs() < 1e-9);
    // No tag: one empty slot, and Q stays at 0.
    let r = round(
        &mut rng,
        &times,
        &[],
        0.0,
        f64::INFINITY,
        &mut Fixed::default(),
    );
    assert_eq!((r.reads.len(), r.slots), (0, [1, 0, 0]));
    assert_eq!(r.qfp, 0.0);
}

#[test]
fn every_tag_is_read_once_at_about_e_slots_per_tag() {
    let times = RfMode::IMPINJ_MODE_2.slot_times(96);
    let n = 200;
    let mut total = [0u32; 3];
    for k in 0..20 {
        let mut rng = seed::stream(&[2, k]);
        let r = round(
            &mut rng,
            &times,
            &tags(n),
            settled_qfp(n),
            f64::INFINITY,
            &mut Fixed::default(),
        );
        let mut seen: Vec<usize> = r.reads.iter().map(|&(_, t)| t).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..n).collect::<Vec<_>>(), "every tag once");
        assert!(r.reads.windows(2).all(|w| w[0].0 < w[1].0));
        for (a, b) in total.iter_mut().zip(r.slots) {
            *a += b;
        }
    }
    // Framed slotted ALOHA with a frame matched to the population needs about e slots per
    // tag (a share 1/e of singles); the Q algorithm keeps close to it.
    let slots = f64::from(total.iter().sum::<u32>()) / (20.0 * n as f64);
    assert!((2.2..3.6).contains(&slots), "{slots} slots per tag");
}

#[test]
fn the_strongest_of_colliding_tags_is_captured_only_well_above_the_rest() {
    let times = RfMode::IMPINJ_MODE_2.slot_times(96);
    let pair = |gap: f64| Fixed {
        levels: vec![-40.0, -40.0 - gap],
        ..Fixed::default()
    };
    // Q = 0: one slot, both answer in it; room for one read.
    let budget = times.query_extra_us + times.success_us;
    let mut rng = seed::stream(&[3]);
    let mut strong_radio = pair(10.0);
    let strong = round(&mut rng, &times, &tags(2), 0.0, budget, &mut strong_radio);
    assert_eq!(strong.reads.len(), 1);
    assert_eq!(strong.reads[0].1, 0);
    assert_eq!(strong.slots, [0, 0, 1]);
    assert_eq!(strong_radio.asked, 1, "the captured reply is decoded");
    // 3 dB apart: the first slot is a collision in which no reply is even tried (and no
    // later one fits a read in the same room).
    let mut close_radio = pair(3.0);
    let close = round(&mut rng, &times, &tags(2), 0.0, budget, &mut close_radio);
    assert!(close.reads.is_empty());
    assert!(
        close.slots[1] >= 1 && close.slots[2] == 0,
        "{:?}",
        close.slots
    );
    assert_eq!(close_radio.asked, 0);
    assert!(close.qfp > 0.0, "a collision raises Q");
}

#[test]
fn tags_that_never_decode_end_the_round_unread() {
    let times = RfMode::IMPINJ_MODE_2.slot_times(96);
    let mut deaf = Fixed {
        deaf: true,
        ..Fixed::default()
    };
    let mut rng = seed::stream(&[4]);
    let r = round(&mut rng, &times, &tags(5), 2.0, f64::INFINITY, &mut deaf);
    assert!(r.reads.is_empty());
    assert!(deaf.asked >= 1);
    assert!(r.duration_us.is_finite() && r.duration_us > 0.0);
    // A reply the reader does not decode is a slot it hears nothing in.
    assert_eq!(r.slots[2], 0);
    // A cut round stops within its budget.
    let r = round(
        &mut rng,
        &times,
        &tags(50),
        5.6,
        20_000.0,
        &mut Fixed::default(),
    );
    assert!(r.duration_us <= 20_000.0);
    assert!(!r.reads.is_empty() && r.reads.len() < 50);
}

#[test]
fn rounds_are_deterministic_for_a_seed() {
    let times = RfMode::IMPINJ_MODE_2.slot_times(96);
    let run = |s| {
        round(
            &mut seed::stream(&[s]),
            &times,
            &tags(30),
            4.0,
            f64::INFINITY,
            &mut Fixed::default(),
        )
    };
    assert_eq!(run(9), run(9));
    assert_ne!(run(9).reads, run(10).reads);
}

/// Reads per second, in all and per tag, of back-to-back session-0 rounds (every tag takes
/// part in each) over one simulated second; Qfp carries from round to round.
fn read_rate(mode: RfMode, n: usize) -> (f64, f64) {
    let times = mode.slot_times(96);
    let mut rng = seed::stream(&[5, n as u64]);
    let (mut t, mut reads, mut qfp) = (0.0, 0usize, 4.0);
    let population = tags(n);
    // 10 s: the total's spread from run to run is well under the 2 % the test allows.
    let span = 10e6;
    while t < span {
        let r = round(
            &mut rng,
            &times,
            &population,
            qfp,
            span - t,
            &mut Fixed::default(),
        );
        if r.duration_us <= 0.0 {
            break;
        }
        t += r.duration_us;
        reads += r.reads.len();
        qfp = r.qfp;
    }
    let rate = reads as f64 / (span / 1e6);
    (rate, rate / n as f64)
}

#[test]
fn read_rate_falls_with_population_as_framed_aloha_does() {
    let mut last_total = f64::INFINITY;
    for n in [1, 10, 100, 1000] {
        let (total, per_tag) = read_rate(RfMode::IMPINJ_MODE_2, n);
        println!("mode 2, {n:>4} tags: {total:>6.0} reads/s, {per_tag:>7.2} per tag");
        let (fast, fast_per) = read_rate(RfMode::IMPINJ_MODE_0, n);
        println!("mode 0, {n:>4} tags: {fast:>6.0} reads/s, {fast_per:>7.2} per tag");
        assert!(fast > total);
        // A lone tag gets a whole slot a round; many share about 1/e of the slots.
        assert!(
            total <= last_total * 1.02,
            "{n}: {total} after {last_total}"
        );
        last_total = total;
    }
    let (one, _) = read_rate(RfMode::IMPINJ_MODE_2, 1);
    let (many, per) = read_rate(RfMode::IMPINJ_MODE_2, 1000);
    assert!((200.0..300.0).contains(&one), "{one}");
    assert!(many > 0.4 * one && many < one, "{many}");
    assert!(per < 0.3, "{per}");
}
