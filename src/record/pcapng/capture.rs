//! Reading a capture file as a stream: pcap or pcapng (told apart by their magic number)
//! through pcap-parser's readers, which hold one buffer of the file at a time, so a capture
//! larger than memory is read in bounded memory. Each packet comes with its link type and
//! its time in UTC microseconds (pcap-parser's pcapng time resolutions: `if_tsresol` as a
//! power of 10 up to 10^-19 s or of 2 up to 2^-63 s, and `if_tsoffset`).

use std::io::{Cursor, Read};

use pcap_parser::pcapng::Block;
use pcap_parser::traits::PcapReaderIterator;
use pcap_parser::{LegacyPcapReader, PcapBlockOwned, PcapError, PcapNGReader};

use super::packet::Link;
use super::ImportError;

/// One captured packet.
#[derive(Clone, Debug)]
pub struct Packet<'a> {
    /// 1-based number in the capture (as Wireshark counts).
    pub number: usize,
    /// When it was captured, UTC µs since the Unix epoch.
    pub utc_us: u64,
    /// Its link type: `Ok` if supported, else the pcap link-type number.
    pub link: Result<Link, u32>,
    /// The bytes captured.
    pub data: &'a [u8],
    /// Whether fewer bytes were captured than the packet had (the snap length).
    pub cut: bool,
}

/// The pcapng Section Header Block type, as the file's first four bytes (either byte order).
const PCAPNG_MAGIC: [u8; 4] = [0x0A, 0x0D, 0x0D, 0x0A];

/// The reader's first buffer; it grows (doubling) for a larger block.
const BUFFER: usize = 1 << 20;

/// The largest block taken: past this a block length is taken as corrupt.
pub const MAX_BLOCK: usize = 256 << 20;

/// An interface of a pcapng section: its link, ticks per second and offset in seconds.
#[derive(Clone, Copy, Debug)]
struct Interface {
    link: Result<Link, u32>,
    ticks_per_s: Option<u64>,
    offset_s: i64,
}

/// What the blocks read so far say about the ones to come.
#[derive(Debug, Default)]
struct State {
    /// The legacy pcap's link and whether its fractions are nanoseconds.
    legacy: Option<(Result<Link, u32>, bool)>,
    /// The pcapng section's interfaces and byte order.
    interfaces: Vec<Interface>,
    big_endian: bool,
    /// Packets so far, and the last one's time (a Simple Packet Block has none).
    packets: usize,
    last_us: u64,
}

/// Reads every packet of the pcap or pcapng capture `input`, one at a time, handing each to
/// `each` (which may stop the reading with an error); returns what was tolerated (a capture
/// cut inside its last packet).
pub fn read_packets<R: Read + Send>(
    mut input: R,
    mut each: impl FnMut(&Packet<'_>) -> Result<(), ImportError>,
) -> Result<Vec<String>, ImportError> {
    let start = prefix(&mut input)?;
    let magic = start.get(..4).ok_or_else(|| not_a_capture(&start))?;
    let pcapng = magic == PCAPNG_MAGIC;
    let pcap = [
        [0xA1, 0xB2, 0xC3, 0xD4],
        [0xD4, 0xC3, 0xB2, 0xA1],
        [0xA1, 0xB2, 0x3C, 0x4D],
        [0x4D, 0x3C, 0xB2, 0xA1],
        [0xA1, 0xB2, 0xCD, 0x34],
        [0x34, 0xCD, 0xB2, 0xA1],
    ]
    .iter()
    .any(|m| m == magic);
    if !pcapng && !pcap {
        return Err(not_a_capture(&start));
    }
    let input = Cursor::new(start).chain(input);
    let at_start = |e: PcapError<&'static [u8]>| malformed(0, 0, &e);
    let mut it: Box<dyn PcapReaderIterator + Send> = if pcapng {
        Box::new(PcapNGReader::new(BUFFER, input).map_err(at_start)?)
    } else {
        Box::new(LegacyPcapReader::new(BUFFER, input).map_err(at_start)?)
    };
    let mut state = State::default();
    let mut capacity = BUFFER;
    loop {
        let err = match it.next() {
            Ok((size, block)) => {
                state.block(block, &mut each)?;
                it.consume(size);
                continue;
            }
            Err(e) => Stop::of(e),
        };
        let at = it.consumed();
        match err {
            Stop::End => return Ok(Vec::new()),
            Stop::Cut => return Ok(vec![cut(at, it.data().len())]),
            Stop::More if it.data().len() < capacity => {
                it.refill().map_err(|e| malformed(at, state.packets, &e))?
            }
            Stop::More if capacity < MAX_BLOCK => {
                capacity *= 2;
                it.grow(capacity);
            }
            Stop::More => return Err(too_large(at, state.packets)),
            Stop::Bad(reason) => {
                return Err(ImportError::Pcap {
                    offset: at,
                    after: state.packets,
                    reason,
                })
            }
        }
    }
}

/// How a read that gave no block ended.
enum Stop {
    /// The end of the file, after a whole block.
    End,
    /// The end of the file, inside a block.
    Cut,
    /// The buffer needs more of the file, or to grow.
    More,
    /// A block that does not parse, and why.
    Bad(String),
}

impl Stop {
    fn of(e: PcapError<&[u8]>) -> Stop {
        match e {
            PcapError::Eof => Stop::End,
            PcapError::UnexpectedEof => Stop::Cut,
            PcapError::Incomplete(_) | PcapError::BufferTooSmall => Stop::More,
            other => Stop::Bad(reason(&other)),
        }
    }
}

/// What a pcap-parser error says, without the input it quotes.
fn reason<I>(e: &PcapError<I>) -> String {
    match e {
        PcapError::NomError(_, kind) | PcapError::OwnedNomError(_, kind) => {
            format!("a block that does not parse ({kind:?})")
        }
        PcapError::ReadError => "the file could not be read".into(),
        PcapError::HeaderNotRecognized => "a header that is neither pcap nor pcapng".into(),
        PcapError::Eof | PcapError::UnexpectedEof => "the file ends early".into(),
        PcapError::Incomplete(_) | PcapError::BufferTooSmall => "a block cut short".into(),
    }
}

fn malformed<I>(offset: usize, after: usize, e: &PcapError<I>) -> ImportError {
    ImportError::Pcap {
        offset,
        after,
        reason: reason(e),
    }
}

fn too_large(offset: usize, after: usize) -> ImportError {
    ImportError::Pcap {
        offset,
        after,
        reason: format!(
            "a block longer than {} MiB, the most this importer takes",
            MAX_BLOCK >> 20
        ),
    }
}

/// The first bytes of `input` (up to the reader's first buffer): the magic number, and the
/// first block whole, which pcap-parser's readers parse from their first read.
fn prefix(input: &mut impl Read) -> Result<Vec<u8>, ImportError> {
    let mut start = Vec::new();
    input
        .take(BUFFER as u64)
        .read_to_end(&mut start)
        .map_err(|e| ImportError::Read(e.to_string()))?;
    Ok(start)
}

fn not_a_capture(data: &[u8]) -> ImportError {
    let start: String = data
        .iter()
        .take(8)
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ");
    let hint = if data.first() == Some(&b'{') {
        " (it looks like JSON: an llrp-gateway recording? `import` reads captures, `export` reads recordings)"
    } else {
        ""
    };
    ImportError::NotACapture {
        start: if start.is_empty() {
            "nothing (an empty file)".into()
        } else {
            start
        },
        hint,
    }
}

/// The warning for a capture that ends inside a packet or block (a capture still being
/// written, or killed).
fn cut(offset: usize, rest: usize) -> String {
    format!(
        "the capture ends inside a packet at byte {offset} (cut short while written?): its last {rest} bytes are ignored"
    )
}

mod blocks;

#[cfg(test)]
mod tests;
