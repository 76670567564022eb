use super::*;
use crate::poses::PoseSample;
use crate::series::Sample;
use llrp_gateway_vocab::pose::Pose;

fn read(epc: &str, t_us: u64, phase: Option<f64>, f: Option<u64>) -> Read {
    Read {
        epc: llrp_gateway_vocab::epc::Epc::parse(epc).expect("hex"),
        reader: Some("r".parse().expect("a reader name")),
        antenna: 1,
        t_us,
        phase_rad: phase,
        rssi_dbm: Some(-50.0),
        channel_index: Some(1),
        channel_frequency_hz: f,
        doppler_hz: None,
        antenna_pose: None,
        last_seen_us: None,
    }
}

#[test]
fn reads_are_filed_by_series_or_set_aside_by_reason() {
    let mut poses = Poses::new();
    for (t, x) in [(0, 0.0), (100_000, 0.01), (200_000, 0.02)] {
        poses.add(PoseSample {
            t_us: t,
            reader: Some("r".parse().expect("a reader name")),
            antenna: 1,
            pose: Pose::from_degrees([x, 1.0, 0.5], x * 1000.0, 0.0),
        });
    }
    let mut ingest = Ingest::new(poses, Ambiguity::None, 1_000_000);
    ingest.push(&read("A1", 50_000, Some(1.0), Some(915_250_000)));
    ingest.push(&read("A1", 150_000, Some(1.1), Some(915_250_000)));
    ingest.push(&read("A1", 160_000, Some(2.0), Some(902_750_000)));
    ingest.push(&read("B2", 60_000, Some(0.3), Some(915_250_000)));
    ingest.push(&read("B2", 70_000, None, Some(915_250_000)));
    ingest.push(&read("B2", 80_000, Some(0.3), None));
    ingest.push(&read("B2", 900_000, Some(0.3), Some(915_250_000)));
    // A read carrying its own pose needs no pose file.
    let mut own = read("C3", 5_000_000, Some(0.5), Some(915_250_000));
    own.antenna_pose = Some(Pose::from_degrees([3.0, 0.0, 1.0], 0.0, 0.0));
    ingest.push(&own);
    assert_eq!(ingest.taken(), 5);
    assert_eq!(
        ingest.set_aside(),
        SetAside {
            no_phase: 1,
            no_frequency: 1,
            no_pose: 1,
            weak: 0
        }
    );
    // A1 on two channels: two series; B2 and C3 one each.
    assert_eq!(ingest.series().count(), 4);
    let key = (
        llrp_gateway_vocab::epc::Epc::parse("A1").expect("hex"),
        "r".to_string(),
        1,
        915_250_000,
    );
    let (_, a1) = ingest
        .series()
        .find(|(k, _)| **k == key)
        .expect("A1's series");
    let seg = a1.segments().next().expect("a segment");
    assert_eq!(seg.len(), 2);
    // The antenna position interpolated at each read: x = 0.005 and 0.015.
    assert!((seg[0].antenna[0] - 0.005).abs() < 1e-12);
    assert!((seg[1].antenna[0] - 0.015).abs() < 1e-12);
    // With its yaw, interpolated too (5° and 15°), and the phase as reported.
    assert!((seg[0].yaw_rad - 5f64.to_radians()).abs() < 1e-12);
    assert!((seg[1].yaw_rad - 15f64.to_radians()).abs() < 1e-12);
    assert_eq!((seg[0].raw_phase_rad, seg[1].raw_phase_rad), (1.0, 1.1));
}

#[test]
fn reads_under_the_rssi_floor_are_set_aside_and_counted() {
    let mut ingest =
        Ingest::new(Poses::new(), Ambiguity::None, 1_000_000).with_min_rssi(Some(-65.0));
    let with = |t_us: u64, rssi: Option<f64>| Read {
        rssi_dbm: rssi,
        ..posed("A1", t_us, 0.001 * t_us as f64 / 1000.0, 915_250_000)
    };
    for (t, rssi) in [
        (0, Some(-50.0)),
        (1_000, Some(-65.0)),
        (2_000, Some(-65.01)),
        (3_000, Some(-80.0)),
        (4_000, None),
    ] {
        ingest.push(&with(t, rssi));
    }
    // At the floor and above, and without RSSI: filed; under it: set aside.
    assert_eq!(ingest.taken(), 3);
    assert_eq!(ingest.set_aside().weak, 2);
    assert_eq!(ingest.set_aside().total(), 2);
    let (_, series) = ingest.series().next().expect("A1's series");
    let times: Vec<u64> = series.samples().iter().map(|s| s.t_us).collect();
    assert_eq!(times, [0, 1_000, 4_000]);
    // No floor: every read filed.
    let mut all = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
    for t in [2_000, 3_000] {
        all.push(&with(t, Some(-80.0)));
    }
    assert_eq!((all.taken(), all.set_aside().weak), (2, 0));
}

#[test]
fn extending_by_a_slice_files_as_pushing_each_read() {
    // Two tags on two channels, interleaved, with a late read among them.
    let mut reads: Vec<Read> = (0..40u64)
        .map(|k| {
            let (epc, f) = if k % 3 == 0 {
                ("A1", 915_250_000)
            } else {
                ("B2", 902_750_000)
            };
            posed(epc, k * 10_000, 0.004 * k as f64, f)
        })
        .collect();
    reads.swap(20, 22);
    let mut one_by_one = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
    for r in &reads {
        one_by_one.push(r);
    }
    let mut extended = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
    extended.extend(&reads);
    assert_eq!(extended.taken(), 40);
    let series = |i: &Ingest| -> Vec<(Key, Vec<Sample>)> {
        i.series()
            .map(|(k, s)| (k.clone(), s.samples().to_vec()))
            .collect()
    };
    assert_eq!(series(&extended), series(&one_by_one));
    assert_eq!(series(&extended).len(), 2);
}

#[test]
fn readers_sharing_a_port_and_channel_keep_their_series_and_their_own_tracks() {
    // Two readers on port 1, and reader "r" on 70 ports (more than a batch remembers):
    // each antenna's track at its own x, y = port.
    let mut poses = Poses::new();
    let antennas: Vec<(&str, u16, f64)> = std::iter::once(("q", 1, 5.0))
        .chain((1..=70).map(|port| ("r", port, 0.1 * f64::from(port))))
        .collect();
    for &(reader, antenna, x) in &antennas {
        for t in [0, 100_000] {
            poses.add(PoseSample {
                t_us: t,
                reader: Some(reader.parse().expect("a reader name")),
                antenna,
                pose: Pose::from_degrees([x, f64::from(antenna), 0.5], 0.0, 0.0),
            });
        }
    }
    let reads: Vec<Read> = (0..3u64)
        .flat_map(|k| {
            antennas.iter().map(move |&(reader, antenna, _)| Read {
                reader: Some(reader.parse().expect("a reader name")),
                antenna,
                ..read("A1", 1_000 + k * 1_000, Some(0.5), Some(915_250_000))
            })
        })
        .collect();
    let mut ingest = Ingest::new(poses, Ambiguity::None, 1_000_000);
    ingest.extend(&reads);
    assert_eq!(ingest.taken(), reads.len() as u64);
    assert_eq!(ingest.series().count(), antennas.len());
    for &(reader, antenna, x) in &antennas {
        let key = (
            llrp_gateway_vocab::epc::Epc::parse("A1").expect("hex"),
            reader.to_string(),
            antenna,
            915_250_000,
        );
        let (_, series) = ingest
            .series()
            .find(|(k, _)| **k == key)
            .expect("its series");
        assert_eq!(series.len(), 3, "{reader} port {antenna}");
        for s in series.samples() {
            assert_eq!([s.antenna[0], s.antenna[1]], [x, f64::from(antenna)]);
        }
    }
}

/// A read of phase 0.5 rad carrying its own pose: the antenna at `x` on the x axis.
fn posed(epc: &str, t_us: u64, x: f64, f_hz: u64) -> Read {
    let mut r = read(epc, t_us, Some(0.5), Some(f_hz));
    r.antenna_pose = Some(Pose::from_degrees([x, 1.0, 0.5], 0.0, 0.0));
    r
}

#[test]
fn a_tag_of_two_phase_segments_stays_within_its_bound_and_keeps_its_newest_reads() {
    let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000);
    let bound = 4096;
    // Pairs of reads on 50 channels in turn, a gap longer than the series allows
    // between visits: every segment holds two phases, which thinning cannot halve.
    let mut most = 0;
    for k in 0..20_000u64 {
        let f = 902_750_000 + (k / 2 % 50) * 500_000;
        let r = posed("A1", k * 10_000, 0.0, f);
        ingest.push(&r);
        ingest.bound_tag("A1", bound);
        most = most.max(ingest.tag_samples("A1"));
    }
    assert!(most <= bound, "held {most}");
    assert!(ingest.tag_samples("A1") >= bound / 2);
    let newest = ingest
        .tag_series("A1")
        .filter_map(|(_, s)| s.segments().last()?.last().map(|x| x.t_us))
        .max();
    assert_eq!(newest, Some(19_999 * 10_000));
}

#[test]
fn a_trimmed_tags_emptied_series_is_forgotten_and_the_others_still_found() {
    let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000);
    let (f1, f2) = (902_750_000, 903_250_000);
    // A1's series on f1 first (oldest), then B2's on f1 and f2, then A1's on f2.
    ingest.push(&posed("A1", 0, 0.0, f1));
    ingest.push(&posed("B2", 10, 0.0, f1));
    ingest.push(&posed("B2", 20, 0.0, f2));
    for k in 0..4 {
        ingest.push(&posed("A1", 100_000 + k * 10, 0.0, f2));
    }
    // Down to 4 phases: A1's oldest segment, all of its f1 series, goes.
    ingest.trim_tag("A1", 4);
    fn channels(ingest: &Ingest, epc: &str) -> Vec<(u64, usize)> {
        let of_tag = ingest.tag_series(epc);
        of_tag.map(|(k, s)| (k.3, s.len())).collect()
    }
    assert_eq!(channels(&ingest, "A1"), vec![(f2, 4)]);
    assert_eq!(channels(&ingest, "B2"), vec![(f1, 1), (f2, 1)]);
    // A read of the series moved into the forgotten one's place goes to it.
    ingest.push(&posed("B2", 30, 0.0, f2));
    ingest.push(&posed("A1", 100_100, 0.0, f1));
    assert_eq!(channels(&ingest, "B2"), vec![(f1, 1), (f2, 2)]);
    assert_eq!(channels(&ingest, "A1"), vec![(f1, 1), (f2, 4)]);
    assert_eq!(ingest.tags().collect::<Vec<_>>(), vec!["A1", "B2"]);
    assert_eq!(ingest.series().count(), 4);
}

#[test]
fn a_tag_of_long_segments_is_thinned_and_keeps_its_oldest_read() {
    let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
    // One pass, a read every 10 ms moving 1 mm: a single segment.
    for k in 0..20_000u64 {
        ingest.push(&posed("B2", k * 10_000, k as f64 * 0.001, 915_250_000));
        ingest.bound_tag("B2", 4096);
    }
    let (_, s) = ingest.tag_series("B2").next().expect("a series");
    assert_eq!(s.segments().len(), 1);
    assert!(s.len() <= 4096);
    assert_eq!(s.samples()[0].t_us, 0, "the aperture stays");
}

#[test]
fn a_parked_antennas_reads_do_not_thin_away_the_pass_before_it() {
    let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
    // The drive: 1,200 reads 1 cm apart (one segment); then the robot parks at its end and
    // reads the tag 30,000 times more from there (S1's end of drive at 100 reads a second).
    let end = 11.99;
    for k in 0..1_200u64 {
        ingest.push(&posed("C3", k * 10_000, k as f64 * 0.01, 915_250_000));
        ingest.bound_tag("C3", 4096);
    }
    for k in 1_200..31_200u64 {
        ingest.push(&posed("C3", k * 10_000, end, 915_250_000));
        ingest.bound_tag("C3", 4096);
    }
    assert!(ingest.tag_samples("C3") <= 4096);
    let samples: Vec<Sample> = ingest
        .tag_series("C3")
        .flat_map(|(_, s)| s.samples().to_vec())
        .collect();
    let moving = samples
        .iter()
        .filter(|s| s.antenna[0] < end - 0.005)
        .count();
    assert_eq!(moving, 1_199, "every read of the drive is kept");
    assert_eq!(
        samples.last().map(|s| s.t_us),
        Some(31_199 * 10_000),
        "the newest read stays (the next one is unwrapped against it)"
    );
}

#[test]
fn a_parked_robots_wandering_pose_estimate_does_not_trim_away_the_pass_before_it() {
    // As above, but the parked antenna's position is a robot's own estimate, wandering a
    // couple of centimetres (no two reads at one place), and the channel changes every 40
    // reads with a gap between visits: short segments, which thinning cannot make room
    // among, so segments are dropped. Those read from one place go before the drive's.
    let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 100_000);
    let end = 11.99;
    for k in 0..1_200u64 {
        ingest.push(&posed("C4", k * 10_000, k as f64 * 0.01, 915_250_000));
        ingest.bound_tag("C4", 4096);
    }
    for k in 1_200..31_200u64 {
        let wander = 0.02 * ((k as f64) * 0.002).sin() + 0.0005 * (k % 7) as f64;
        let f = 902_750_000 + (k / 40 % 50) * 500_000;
        let t = k * 10_000 + (k / 40) * 200_000;
        ingest.push(&posed("C4", t, end + wander, f));
        ingest.bound_tag("C4", 4096);
    }
    assert!(ingest.tag_samples("C4") <= 4096);
    let samples: Vec<Sample> = ingest
        .tag_series("C4")
        .flat_map(|(_, s)| s.samples().to_vec())
        .collect();
    let drive = samples.iter().filter(|s| s.antenna[0] < end - 0.05).count();
    assert!(drive >= 300, "{drive} reads of the drive left");
    assert_eq!(
        samples.iter().map(|s| s.t_us).min(),
        Some(0),
        "the drive's first read stays"
    );
}
