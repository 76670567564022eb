//! The feed: what any source of reads (the simulator, the proxy, a replay, the inventory
//! client) hands any consumer (the localizer, an MQTT publisher): [`Input`], through a [`Tap`]
//! that never waits and counts what it drops, with copies for mirrors ([`Mirror`]); and each
//! reader's link ([`Links`]), which a source writes and a consumer shows.

use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::Arc;

use bytes::Bytes;
use llrp::units::HopTable;
use prometheus_client::metrics::counter::Counter;
use serde::Serialize;

use crate::pose::PoseSample;
use crate::reader_name::ReaderName;
use crate::reads::Read;

mod links;

pub use links::{Inventory, Link, Links};

/// What a source hands on: to the localizer, and to any mirror beside it.
#[derive(Clone, Debug)]
pub enum Input {
    /// A reader is known by this name; its reads' channels are looked up in `hop_table`
    /// until its own capabilities response is seen.
    Reader {
        /// The reader's name.
        name: ReaderName,
        /// The hop table the reader advertises, when known beforehand.
        hop_table: Option<HopTable>,
        /// Its antenna ports.
        antennas: Vec<u16>,
        /// Reader time − robot time for its poses (µs).
        clock_offset_us: i64,
        /// Its antennas' poses at its reads, where the source knows them (a simulator):
        /// its reads then need no pose sample.
        poses: Option<crate::reads::PoseAt>,
    },
    /// Whole LLRP frames reader `reader` sent to its client.
    Frames {
        /// The reader's name.
        reader: ReaderName,
        /// The frames, back to back.
        bytes: Bytes,
        /// Arrival time to stamp reads that carry no timestamp (UTC µs).
        now_utc_us: u64,
    },
    /// Reads already decoded (a proxy's tap, a recording, a reads file).
    Reads(Vec<Read>),
    /// Antenna pose samples (a simulator, a pose file, `POST /api/poses`).
    Poses(Vec<PoseSample>),
    /// A simulation's ground truth now (the localizer shows it beside its estimates).
    Truth(Truth),
    /// Reader `reader` came (its upstream connection is up) or went.
    Status {
        /// The reader's name.
        reader: ReaderName,
        /// Up or gone.
        online: bool,
    },
    /// A READER_EVENT_NOTIFICATION a proxied reader sent (the localizer has no use for it;
    /// an MQTT publisher forwards it).
    Event {
        /// The reader's name.
        reader: ReaderName,
        /// The event.
        data: Box<llrp::params::ReaderEventNotificationData>,
    },
    /// A proxied reader's KEEPALIVEs stopped or came back (the localizer has no use for
    /// it; an MQTT publisher forwards it).
    Keepalive {
        /// The reader's name.
        reader: ReaderName,
        /// Lost (no KEEPALIVE for three periods), or back.
        lost: bool,
        /// The period expected (ms).
        period_ms: u64,
        /// Time without a KEEPALIVE (ms).
        silent_ms: u64,
    },
}

/// Ground truth of a simulation, for `GET /api/truth`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Truth {
    /// Every tag's true position.
    pub tags: Vec<TruthTag>,
    /// Every antenna's true pose now.
    pub antennas: Vec<PoseSample>,
}

/// One tag's true position.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TruthTag {
    /// EPC.
    pub epc: crate::epc::Epc,
    /// Position (m).
    pub position: [f64; 3],
    /// A reference tag (its position is known to the localizer).
    pub reference: bool,
}

impl Input {
    /// How many reads or poses the input counts for when dropped (1 for anything else).
    pub fn weight(&self) -> u64 {
        match self {
            Input::Reads(r) => r.len() as u64,
            Input::Poses(p) => p.len() as u64,
            _ => 1,
        }
    }
}

/// The sending side of the feed, to the localizer and any mirror beside it (such as an MQTT
/// publisher): never waits.
#[derive(Clone, Debug)]
pub struct Tap {
    /// `None`: no localizer runs (a tap for mirrors only).
    tx: Option<SyncSender<Input>>,
    /// Inputs (reads or poses, one by one) the localizer was behind for.
    dropped: Counter,
    links: Arc<Links>,
    mirrors: Vec<Mirror>,
}

/// Another consumer of everything a [`Tap`] is offered, with its own bound and drop count.
#[derive(Clone, Debug)]
pub struct Mirror {
    /// Where the copies go.
    pub tx: SyncSender<Input>,
    /// Inputs (reads or poses, one by one) dropped because it was behind.
    pub dropped: Counter,
}

impl Tap {
    /// The tap of a localizer taking its input from `tx`; what it is behind for counts in
    /// `dropped`, and the sources write their readers' links to `links`.
    pub fn new(tx: SyncSender<Input>, dropped: Counter, links: Arc<Links>) -> Tap {
        Tap {
            tx: Some(tx),
            dropped,
            links,
            mirrors: Vec::new(),
        }
    }

    /// A tap with no localizer behind it: what it is offered goes to its mirrors only;
    /// `links` still takes the readers' links.
    pub fn detached(links: Arc<Links>) -> Tap {
        Tap {
            tx: None,
            dropped: Counter::default(),
            links,
            mirrors: Vec::new(),
        }
    }

    /// This tap with `mirror` also offered everything.
    pub fn with_mirror(mut self, mirror: Mirror) -> Tap {
        self.mirrors.push(mirror);
        self
    }

    /// Offers a copy of `input` to every mirror.
    fn mirror(&self, input: &Input) {
        for m in &self.mirrors {
            if m.tx.try_send(input.clone()).is_err() {
                m.dropped.inc_by(input.weight());
            }
        }
    }

    /// Hands `input` to the localizer; `false` (and counted) when it is behind or gone.
    pub fn offer(&self, input: Input) -> bool {
        self.mirror(&input);
        let Some(tx) = &self.tx else {
            return true;
        };
        let weight = input.weight();
        match tx.try_send(input) {
            Ok(()) => true,
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.dropped.inc_by(weight);
                false
            }
        }
    }

    /// Hands `input` to the localizer, or gives it back when it is behind (not counted as
    /// dropped: for a caller that can wait, such as a pose file loaded at start); dropped and
    /// counted when the localizer has stopped. Mirrors are offered a copy once it is taken.
    pub fn try_offer(&self, input: Input) -> Result<(), Input> {
        let Some(tx) = &self.tx else {
            self.mirror(&input);
            return Ok(());
        };
        let copy = (!self.mirrors.is_empty()).then(|| input.clone());
        let taken = match tx.try_send(input) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(i)) => Err(i),
            Err(TrySendError::Disconnected(i)) => {
                // The localizer has stopped: waiting would not help.
                self.dropped.inc_by(i.weight());
                Ok(())
            }
        };
        if let (Ok(()), Some(c)) = (&taken, copy) {
            self.mirror(&c);
        }
        taken
    }

    /// The readers' links the sources behind this tap write.
    pub fn links(&self) -> &Arc<Links> {
        &self.links
    }
}
