//! Presence events per tag (`PREFIX/v1/presence/{epc}`), as a worker sees its tags: `arrived`
//! at the first read (again after a departure), `departed` after a silence with no read,
//! `moved` when the estimate has moved more than a distance from where the last presence
//! event put it. Sans IO: reads, estimates and the time go in, events come out.

use crate::reads::ReaderName;
use llrp_gateway_vocab::reader_name::none_as_empty;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use serde::Serialize;

use super::schema::VERSION;

/// Default silence after which a tag has departed.
pub const DEFAULT_SILENCE: Duration = Duration::from_secs(10);

/// Default distance an estimate moves before a `moved` event (m).
pub const DEFAULT_MOVE_M: f64 = 0.5;

/// One presence event.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct PresenceEvent {
    /// Schema version.
    pub v: u32,
    /// The tag.
    pub epc: String,
    /// `arrived`, `departed` or `moved`.
    pub event: &'static str,
    /// The reader of the tag's newest read (`""` when it named none).
    #[serde(serialize_with = "none_as_empty")]
    pub reader: Option<ReaderName>,
    /// Its antenna.
    pub antenna: u16,
    /// The newest read's time (UTC µs, the reads' clock).
    pub last_seen_us: u64,
    /// The tag's estimated position, when it has one (m).
    pub position: Option<[f64; 3]>,
}

/// One tag's presence.
#[derive(Clone, Debug)]
struct Tag {
    present: bool,
    last_read: Instant,
    reader: Option<ReaderName>,
    antenna: u16,
    last_seen_us: u64,
    /// The newest estimate.
    position: Option<[f64; 3]>,
    /// Where the last event put it.
    announced: Option<[f64; 3]>,
}

/// The presence of every tag a worker holds.
#[derive(Debug)]
pub struct Presence {
    silence: Duration,
    move_m: f64,
    tags: BTreeMap<String, Tag>,
}

impl Presence {
    /// Departures after `silence` without a read; `moved` beyond `move_m`.
    pub fn new(silence: Duration, move_m: f64) -> Presence {
        Presence {
            silence,
            move_m,
            tags: BTreeMap::new(),
        }
    }

    fn event(epc: &str, t: &Tag, event: &'static str) -> PresenceEvent {
        PresenceEvent {
            v: VERSION,
            epc: epc.to_owned(),
            event,
            reader: t.reader.clone(),
            antenna: t.antenna,
            last_seen_us: t.last_seen_us,
            position: t.position,
        }
    }

    /// A read of `epc` by `reader`'s `antenna` at `t_us`, taken at `now`: `arrived` when the
    /// tag was not present.
    pub fn read(
        &mut self,
        epc: &str,
        reader: Option<&ReaderName>,
        antenna: u16,
        t_us: u64,
        now: Instant,
    ) -> Option<PresenceEvent> {
        let t = self.tags.entry(epc.to_owned()).or_insert_with(|| Tag {
            present: false,
            last_read: now,
            reader: reader.cloned(),
            antenna,
            last_seen_us: t_us,
            position: None,
            announced: None,
        });
        t.last_read = now;
        if t_us >= t.last_seen_us {
            t.last_seen_us = t_us;
            if t.reader.as_ref() != reader {
                t.reader = reader.cloned();
            }
            t.antenna = antenna;
        }
        if t.present {
            return None;
        }
        t.present = true;
        t.announced = t.position;
        Some(Presence::event(epc, t, "arrived"))
    }

    /// The estimate of `epc` is now `position`: `moved` when it is more than the distance
    /// from where the last event put it (or the tag had none).
    pub fn estimate(&mut self, epc: &str, position: [f64; 3]) -> Option<PresenceEvent> {
        let t = self.tags.get_mut(epc)?;
        t.position = Some(position);
        if !t.present {
            return None;
        }
        let far = match t.announced {
            Some(a) => {
                let d = (0..3)
                    .map(|i| (a[i] - position[i]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                d > self.move_m
            }
            None => true,
        };
        if !far {
            return None;
        }
        t.announced = Some(position);
        Some(Presence::event(epc, t, "moved"))
    }

    /// The tags silent for longer than the silence at `now`: `departed`.
    pub fn tick(&mut self, now: Instant) -> Vec<PresenceEvent> {
        let mut out = Vec::new();
        for (epc, t) in &mut self.tags {
            if t.present && now.saturating_duration_since(t.last_read) > self.silence {
                t.present = false;
                out.push(Presence::event(epc, t, "departed"));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reader() -> Option<ReaderName> {
        Some("r".parse().expect("a reader name"))
    }

    #[test]
    fn a_tag_arrives_once_moves_beyond_the_distance_and_departs_after_the_silence() {
        let t0 = Instant::now();
        let s = Duration::from_secs(10);
        let mut p = Presence::new(s, 0.5);
        let r = reader();
        let a = p.read("E1", r.as_ref(), 1, 100, t0).expect("arrived");
        assert_eq!((a.event, a.position), ("arrived", None));
        assert_eq!(p.read("E1", r.as_ref(), 2, 200, t0 + s / 2), None);
        // The first estimate is news; a small change is not; a large one is.
        let m = p.estimate("E1", [1.0, 2.0, 0.0]).expect("moved");
        assert_eq!((m.event, m.antenna, m.last_seen_us), ("moved", 2, 200));
        assert_eq!(p.estimate("E1", [1.3, 2.0, 0.0]), None);
        assert_eq!(
            p.estimate("E1", [1.6, 2.0, 0.0]).map(|e| e.event),
            Some("moved")
        );
        // Silent for less than the silence: still here; past it: departed, once.
        assert!(p.tick(t0 + s).is_empty());
        let d = p.tick(t0 + s / 2 + s + Duration::from_millis(1));
        assert_eq!(d.len(), 1);
        assert_eq!(
            (d[0].event, d[0].position),
            ("departed", Some([1.6, 2.0, 0.0]))
        );
        assert!(p.tick(t0 + 3 * s).is_empty());
        // Read again: arrived again, where it was last estimated.
        let again = p
            .read("E1", r.as_ref(), 1, 900, t0 + 3 * s)
            .expect("arrived");
        assert_eq!(
            (again.event, again.position),
            ("arrived", Some([1.6, 2.0, 0.0]))
        );
    }

    #[test]
    fn an_estimate_of_an_unknown_tag_is_no_event() {
        let mut p = Presence::new(DEFAULT_SILENCE, DEFAULT_MOVE_M);
        assert_eq!(p.estimate("E9", [0.0; 3]), None);
    }
}
