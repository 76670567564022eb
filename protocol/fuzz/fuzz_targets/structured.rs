//! Builds frames with structure, not random bytes, and checks how they decode.
//!
//! The first input byte picks one of two ways to build a frame (bit 0), and its size limit
//! (bit 7: 72 KiB, room for a full TLV; or 1.25 MiB, room for more than 65535 sub-parameters
//! in a message body).
//!
//! * **Program** (even): the rest of the input is a small program run on an explicit stack
//!   (no recursion): open a TLV parameter of any known TLV type, an unknown type or a Custom
//!   (Impinj or another vendor); close it (its length computed, now and then off by a
//!   little); add a TV parameter of a valid TV type; add field bytes, or a counted array of
//!   up to 65535 elements; repeat the last parameter N times or as often as fits (maximal
//!   counts, up to a TLV's 65535 bytes); open ParameterErrors k deep, or wrap the last
//!   parameter in k of them (k up to [`MAX_FITTING_NESTING`]). The message type is any typed
//!   one (standard or Impinj custom) or any other number.
//! * **Seeded** (odd): the next 9 bytes seed [`Gen`] and pick a typed message, which is
//!   encoded; the rest of the input then edits its parameter tree: wrap a parameter in k
//!   levels of ParameterError (or another type), duplicate one many times, move or copy one
//!   to another place, drop one. Every enclosing length is fixed up. (The tree is found
//!   without knowing the fields' layout, so now and then a field is taken for a parameter
//!   and the edit mangles it.)
//!
//! Then the frame is decoded:
//!
//! * what decodes must encode to the identical bytes, and serialize to JSON. The one change
//!   allowed is cleared bits: the codec writes reserved bits as 0 (the spec has receivers
//!   ignore them), so a frame with one set comes back with it cleared, and that form must
//!   decode to the same message and re-encode to itself;
//! * what does not decode must be refused at an offset inside the frame, with an LLRPStatus
//!   that, sent back in an ERROR_MESSAGE, decodes again to the same message.
//!
//! `STRUCTURED_DUMP=1` in the environment prints each frame in hex (to read a crash).
#![no_main]

use libfuzzer_sys::fuzz_target;
use llrp::codec::tv_value_len;
use llrp::message::{ErrorMessage, MessageBody};
use llrp::params::KNOWN_TLV_TYPES;
use llrp::sample::{Gen, MAX_FITTING_NESTING};
use llrp::{FrameHeader, Message};

/// Largest frame built: a full TLV and more (with the sanitizers, decoding, encoding and
/// serializing a frame full of small parameters takes about 20 µs a parameter).
const MAX_FRAME: usize = 73_728;
/// Largest frame built when the first input byte has its top bit set: room for more than
/// 65535 small sub-parameters in one message body (one such frame takes about two seconds).
const LARGE_FRAME: usize = 1_310_720;
/// Largest TLV parameter (its length field is 16 bits).
const MAX_TLV: usize = u16::MAX as usize;
const PARAMETER_ERROR: u16 = 289;
const CUSTOM: u16 = 1023;
const IMPINJ: u32 = 25882;
/// Subtypes of the Custom parameters the codec types for Impinj.
const IMPINJ_SUBTYPES: [u32; 20] = [
    21, 22, 23, 26, 27, 28, 29, 30, 37, 50, 51, 52, 53, 54, 55, 56, 57, 65, 67, 68,
];
/// TLV types the codec does not know (kept raw), and vendors it does not type.
const UNKNOWN_TLV_TYPES: [u16; 6] = [0, 127, 130, 290, 900, 1022];
const OTHER_VENDORS: [u32; 3] = [0, 161, 4242];

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let mut input = Input(rest);
    let max_frame = if mode & 0x80 == 0 {
        MAX_FRAME
    } else {
        LARGE_FRAME
    };
    let frame = if mode % 2 == 0 {
        program(&mut input, max_frame)
    } else {
        seeded(&mut input, max_frame)
    };
    if std::env::var_os("STRUCTURED_DUMP").is_some() {
        eprintln!(
            "frame ({} bytes): {}",
            frame.len(),
            llrp::raw::to_hex(&frame)
        );
    }
    check(&frame);
});

/// Decodes `frame` and checks the result (see the top of the file).
fn check(frame: &[u8]) {
    match Message::decode(frame) {
        Ok(m) => {
            let again = m.to_bytes();
            if again[..] != frame[..] {
                // Reserved bits are not kept: the codec writes them as 0 (the spec has the
                // receiver ignore them). Clearing bits must be the only change, and the
                // cleared form must be stable.
                let cleared =
                    again.len() == frame.len() && again.iter().zip(frame).all(|(a, f)| a & !f == 0);
                if !cleared {
                    let at = again.iter().zip(frame).position(|(a, f)| a != f);
                    panic!(
                        "{} re-encodes to other bytes: {} bytes instead of {}, first difference at {at:?}",
                        m.name(),
                        again.len(),
                        frame.len()
                    );
                }
                let back = Message::decode(&again).expect("the re-encoded message decodes");
                assert_eq!(back, m, "clearing reserved bits changed the message");
                assert!(back.to_bytes() == again, "re-encoding is not stable");
            }
            serde_json::to_string(&m).expect("a decoded message serializes to JSON");
        }
        Err(e) => {
            assert!(
                e.offset <= frame.len(),
                "offset {} past the frame",
                e.offset
            );
            let answer = Message::new(
                7,
                ErrorMessage {
                    llrp_status: e.to_status(),
                    ..Default::default()
                },
            );
            let bytes = answer.to_bytes();
            match Message::decode(&bytes) {
                Ok(back) => assert_eq!(back, answer, "the ERROR_MESSAGE decodes differently"),
                Err(e2) => panic!("the ERROR_MESSAGE answering `{e}` does not decode: {e2}"),
            }
        }
    }
}

/// The fuzz input, read front to back; zeros once it runs out.
struct Input<'a>(&'a [u8]);

impl Input<'_> {
    fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    fn u8(&mut self) -> u8 {
        let Some((&b, rest)) = self.0.split_first() else {
            return 0;
        };
        self.0 = rest;
        b
    }
    fn u16(&mut self) -> u16 {
        u16::from_be_bytes([self.u8(), self.u8()])
    }
    fn u32(&mut self) -> u32 {
        u32::from_be_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }
    fn u64(&mut self) -> u64 {
        (u64::from(self.u32()) << 32) | u64::from(self.u32())
    }
    /// Up to `n` bytes (fewer if the input runs out).
    fn bytes(&mut self, n: usize) -> &[u8] {
        let (head, rest) = self.0.split_at(n.min(self.0.len()));
        self.0 = rest;
        head
    }
    /// A count up to `max`: mostly below 8, often around the nesting limit (56 to 71),
    /// sometimes any 16-bit number, sometimes `max` itself (as many as fit).
    fn count(&mut self, max: usize) -> usize {
        let n = match self.u8() {
            0..=127 => usize::from(self.u8() % 8),
            128..=191 => 56 + usize::from(self.u8() % 16),
            192..=254 => usize::from(self.u16()),
            255 => max,
        };
        n.min(max)
    }
    /// One of `items`.
    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[usize::from(self.u16()) % items.len()]
    }
}

/// A TLV type: mostly a known one, sometimes an unknown one or Custom.
fn tlv_type(input: &mut Input) -> u16 {
    match input.u8() {
        0..=219 => input.pick(KNOWN_TLV_TYPES),
        220..=239 => PARAMETER_ERROR,
        240..=247 => CUSTOM,
        _ => input.pick(&UNKNOWN_TLV_TYPES),
    }
}

/// Appends a message header (length patched later) and, for CUSTOM_MESSAGE, vendor and
/// subtype.
fn message_header(input: &mut Input, out: &mut Vec<u8>) {
    let version = match input.u8() {
        0..=250 => 1 + input.u8() % 2,
        v => v % 8,
    };
    let (msg_type, vendor, subtype) = if input.u8() < 240 {
        let (ty, vendor, subtype, _) = input.pick(MessageBody::TYPED);
        (ty, vendor, subtype)
    } else {
        (input.u16() & 0x3FF, IMPINJ, input.u8())
    };
    let id = input.u32();
    FrameHeader {
        version,
        msg_type,
        length: 0,
        id,
    }
    .encode(out);
    if msg_type == CUSTOM {
        out.extend_from_slice(&vendor.to_be_bytes());
        out.push(subtype);
    }
}

/// Writes the frame's length into its header.
fn patch_frame_length(out: &mut [u8]) {
    let len = u32::try_from(out.len()).expect("frames stay small");
    out[2..6].copy_from_slice(&len.to_be_bytes());
}

/// Appends a TLV header (length 0 until closed) for `ty`; Custom gets vendor and subtype.
fn open_tlv(input: &mut Input, out: &mut Vec<u8>, ty: u16) {
    out.extend_from_slice(&ty.to_be_bytes());
    out.extend_from_slice(&[0, 0]);
    if ty == CUSTOM {
        let (vendor, subtype) = if input.u8() < 200 {
            (IMPINJ, input.pick(&IMPINJ_SUBTYPES))
        } else {
            (input.pick(&OTHER_VENDORS), input.u32())
        };
        out.extend_from_slice(&vendor.to_be_bytes());
        out.extend_from_slice(&subtype.to_be_bytes());
    }
}

/// The frame being built by [`program`]: bytes, open TLVs and the last whole parameter.
struct Builder {
    out: Vec<u8>,
    /// Largest frame to build.
    max_frame: usize,
    /// Start of each open TLV, outermost first.
    open: Vec<usize>,
    /// Where the last closed or added parameter starts (it ends at `out.len()` until more is
    /// appended; a repeat then copies `out[last.0..last.1]`).
    last: Option<(usize, usize)>,
}

impl Builder {
    /// Bytes that can still be appended without any open TLV passing 65535 bytes (the
    /// outermost is the largest) or the frame passing its maximum.
    fn room(&self) -> usize {
        let frame = self.max_frame.saturating_sub(self.out.len());
        match self.open.first() {
            Some(&start) => frame.min(MAX_TLV - (self.out.len() - start)),
            None => frame,
        }
    }

    /// Appends `bytes` if they fit; returns whether they did.
    fn put(&mut self, bytes: &[u8]) -> bool {
        if bytes.len() > self.room() {
            return false;
        }
        self.out.extend_from_slice(bytes);
        true
    }

    /// Closes the innermost open TLV, its length off by `skew` (0 most of the time).
    fn close(&mut self, skew: i32) {
        let Some(start) = self.open.pop() else {
            return;
        };
        let len = (self.out.len() - start) as i32 + skew;
        let len = len.clamp(0, MAX_TLV as i32) as u16;
        self.out[start + 2..start + 4].copy_from_slice(&len.to_be_bytes());
        self.last = Some((start, self.out.len()));
    }
}

/// Runs the input as a program that builds a frame (see the top of the file).
fn program(input: &mut Input, max_frame: usize) -> Vec<u8> {
    let mut b = Builder {
        out: Vec::with_capacity(256),
        max_frame,
        open: Vec::new(),
        last: None,
    };
    message_header(input, &mut b.out);
    while !input.is_empty() {
        match input.u8() % 12 {
            // Open a TLV parameter.
            0 | 1 | 2 => {
                let ty = tlv_type(input);
                let start = b.out.len();
                if b.room() >= 12 {
                    open_tlv(input, &mut b.out, ty);
                    b.open.push(start);
                }
            }
            // Close the innermost one (its length computed).
            3 | 4 => b.close(0),
            // Close it with a wrong length.
            5 => {
                let skew = i32::from(input.u8() as i8);
                b.close(skew)
            }
            // A TV parameter of a valid type with its value.
            6 => {
                let ty = 1 + input.u8() % 20;
                let n = tv_value_len(ty).expect("TV types 1 to 20 exist");
                let mut tv = vec![0x80 | ty];
                tv.extend_from_slice(input.bytes(n));
                tv.resize(1 + n, 0);
                let start = b.out.len();
                if b.put(&tv) {
                    b.last = Some((start, b.out.len()));
                }
            }
            // Field bytes.
            7 => {
                let n = 1 + usize::from(input.u8() % 16);
                let mut field = input.bytes(n).to_vec();
                field.resize(n, 0);
                b.put(&field);
            }
            // A counted array (u16 count, then elements of 1, 2 or 4 bytes), up to 65535
            // elements or what fits.
            8 => {
                let size = [1usize, 2, 4][usize::from(input.u8() % 3)];
                let fill = input.u8();
                let count = input.count(MAX_TLV.min(b.room().saturating_sub(2) / size));
                let mut array = (count as u16).to_be_bytes().to_vec();
                array.resize(2 + count * size, fill);
                b.put(&array);
            }
            // Repeat the last parameter N times, or as often as it fits.
            9 => {
                if let Some((start, end)) = b.last {
                    let len = end - start;
                    let n = input.count(b.room() / len);
                    if n > 0 {
                        let copy = b.out[start..end].to_vec();
                        b.out.extend_from_slice(&copy.repeat(n));
                        b.last = Some((b.out.len() - len, b.out.len()));
                    }
                }
            }
            // Open k ParameterErrors, each inside the one before (closed by later ops or at
            // the end): ParameterType and ErrorCode fields, then the next.
            10 => {
                let k = input.count(MAX_FITTING_NESTING.min(b.room() / 8));
                let ty = input.u16();
                let code = input.u16();
                for _ in 0..k {
                    b.open.push(b.out.len());
                    b.out.extend_from_slice(&PARAMETER_ERROR.to_be_bytes());
                    b.out.extend_from_slice(&[0, 0]);
                    b.out.extend_from_slice(&ty.to_be_bytes());
                    b.out.extend_from_slice(&code.to_be_bytes());
                }
            }
            // Wrap the last parameter in k ParameterErrors.
            _ => {
                if let Some((start, end)) = b.last.filter(|&(_, end)| end == b.out.len()) {
                    let fits = b.room().min(MAX_TLV - (end - start)) / 8;
                    let k = input.count(MAX_FITTING_NESTING.min(fits));
                    let ty = u16::from_be_bytes([b.out[start], b.out[start + 1]]) & 0x3FF;
                    let mut wrap = Vec::with_capacity(8 * k);
                    for level in 0..k {
                        let len = (end - start + 8 * (k - level)) as u16;
                        wrap.extend_from_slice(&PARAMETER_ERROR.to_be_bytes());
                        wrap.extend_from_slice(&len.to_be_bytes());
                        wrap.extend_from_slice(&ty.to_be_bytes());
                        wrap.extend_from_slice(&200u16.to_be_bytes());
                    }
                    b.out.splice(start..start, wrap);
                    b.last = Some((start, b.out.len()));
                }
            }
        }
    }
    while !b.open.is_empty() {
        b.close(0);
    }
    patch_frame_length(&mut b.out);
    b.out
}

/// A parameter found in an encoded frame.
#[derive(Clone, Copy)]
struct Node {
    start: usize,
    end: usize,
    /// TLV (a container), not TV.
    tlv: bool,
    /// Index of the enclosing parameter; `None` for one in the message body.
    parent: Option<usize>,
}

/// A place a parameter can be put: before `pos`, in `parent` (`None`: the message body).
#[derive(Clone, Copy)]
struct Slot {
    pos: usize,
    parent: Option<usize>,
}

/// Type of the TLV whose header starts `i`.
fn tlv_type_at(i: &[u8]) -> u16 {
    u16::from_be_bytes([i[0], i[1]]) & 0x3FF
}

/// Size of the parameter whose header starts `i`, if `i` starts with a plausible one that
/// fits: a TV of a valid type, or a TLV (Custom with its vendor and subtype).
fn param_size(i: &[u8]) -> Option<usize> {
    let &b0 = i.first()?;
    let size = if b0 & 0x80 != 0 {
        1 + tv_value_len(b0 & 0x7F)?
    } else {
        if i.len() < 4 {
            return None;
        }
        let len = usize::from(u16::from_be_bytes([i[2], i[3]]));
        if len < if tlv_type_at(i) == CUSTOM { 12 } else { 4 } {
            return None;
        }
        len
    };
    (size <= i.len()).then_some(size)
}

/// Where the sub-parameters of `i` start: the first offset from which a chain of plausible
/// parameters ends exactly at the end of `i` (the fields before it are not parsed, so a
/// field can now and then be mistaken for a parameter: the frame is then merely mangled).
fn first_sub_parameter(i: &[u8]) -> Option<usize> {
    (0..i.len().min(512)).find(|&p0| {
        let mut p = p0;
        while p < i.len() {
            match param_size(&i[p..]) {
                Some(n) => p += n,
                None => return false,
            }
        }
        true
    })
}

/// The parameters of a valid frame (at most 4096), found with an explicit stack.
fn parameter_tree(frame: &[u8], body: usize) -> Vec<Node> {
    let mut nodes = Vec::new();
    let mut todo = vec![(body, frame.len(), None)];
    while let Some((start, end, parent)) = todo.pop() {
        let Some(first) = first_sub_parameter(&frame[start..end]) else {
            continue;
        };
        let mut p = start + first;
        while p < end && nodes.len() < 4096 {
            let n = param_size(&frame[p..end]).expect("the chain was checked");
            let tlv = frame[p] & 0x80 == 0;
            nodes.push(Node {
                start: p,
                end: p + n,
                tlv,
                parent,
            });
            if tlv {
                let header = if tlv_type_at(&frame[p..]) == CUSTOM {
                    12
                } else {
                    4
                };
                todo.push((p + header, p + n, Some(nodes.len() - 1)));
            }
            p += n;
        }
    }
    nodes
}

/// Where a parameter can go: before any parameter, or last in the message body or any TLV.
fn slots(nodes: &[Node], frame_len: usize) -> Vec<Slot> {
    let mut slots = vec![Slot {
        pos: frame_len,
        parent: None,
    }];
    for (k, n) in nodes.iter().enumerate() {
        slots.push(Slot {
            pos: n.start,
            parent: n.parent,
        });
        if n.tlv {
            slots.push(Slot {
                pos: n.end,
                parent: Some(k),
            });
        }
    }
    slots
}

/// The TLVs enclosing `parent` (it included), innermost first.
fn ancestors(nodes: &[Node], mut parent: Option<usize>) -> Vec<usize> {
    let mut chain = Vec::new();
    while let Some(k) = parent {
        chain.push(k);
        parent = nodes[k].parent;
    }
    chain
}

/// How many bytes can be added inside `parent` before an enclosing TLV passes 65535 bytes
/// or the frame passes `max_frame`.
fn room_in(frame: &[u8], max_frame: usize, nodes: &[Node], parent: Option<usize>) -> usize {
    ancestors(nodes, parent)
        .iter()
        .map(|&k| MAX_TLV - (nodes[k].end - nodes[k].start))
        .fold(max_frame.saturating_sub(frame.len()), usize::min)
}

/// Adds `delta` to the length of every TLV enclosing `parent` and sets the frame's.
fn grow(frame: &mut [u8], nodes: &[Node], parent: Option<usize>, delta: isize) {
    for k in ancestors(nodes, parent) {
        let at = nodes[k].start + 2;
        let len = u16::from_be_bytes([frame[at], frame[at + 1]]) as isize + delta;
        frame[at..at + 2].copy_from_slice(&(len as u16).to_be_bytes());
    }
    patch_frame_length(frame);
}

/// Encodes a random valid typed message and edits its parameter tree (see the top of the
/// file).
fn seeded(input: &mut Input, max_frame: usize) -> Vec<u8> {
    let seed = input.u64();
    let k = usize::from(input.u8()) % MessageBody::TYPED.len();
    let mut g = Gen::new(seed);
    let message = Message {
        version: 1 + (seed % 2) as u8,
        id: (seed >> 8) as u32,
        body: MessageBody::sample_typed(k, &mut g),
    };
    let mut frame = message.to_bytes().to_vec();
    let body = if message.msg_type() == CUSTOM { 15 } else { 10 };
    for _ in 0..8 {
        if input.is_empty() {
            break;
        }
        let op = input.u8() % 5;
        let nodes = parameter_tree(&frame, body);
        if nodes.is_empty() {
            break;
        }
        let at = usize::from(input.u16()) % nodes.len();
        let node = nodes[at];
        let bytes = frame[node.start..node.end].to_vec();
        let len = bytes.len();
        match op {
            // Wrap it in k levels of ParameterError (or of another TLV type).
            0 => {
                let ty = if input.u8() < 192 {
                    PARAMETER_ERROR
                } else {
                    tlv_type(input)
                };
                let level = if ty == PARAMETER_ERROR { 8 } else { 4 };
                let room = room_in(&frame, max_frame, &nodes, node.parent).min(MAX_TLV - len);
                let k = input.count(MAX_FITTING_NESTING.min(room / level));
                let inner_ty = if node.tlv {
                    tlv_type_at(&bytes)
                } else {
                    u16::from(bytes[0] & 0x7F)
                };
                let mut wrap = Vec::with_capacity(level * k);
                for depth in 0..k {
                    wrap.extend_from_slice(&ty.to_be_bytes());
                    wrap.extend_from_slice(&((len + level * (k - depth)) as u16).to_be_bytes());
                    if ty == PARAMETER_ERROR {
                        // ParameterType, ErrorCode (P_ParameterError).
                        wrap.extend_from_slice(&inner_ty.to_be_bytes());
                        wrap.extend_from_slice(&200u16.to_be_bytes());
                    }
                }
                frame.splice(node.start..node.start, wrap);
                grow(&mut frame, &nodes, node.parent, (level * k) as isize);
            }
            // Duplicate it N times, or as often as fits.
            1 => {
                let n = input.count(room_in(&frame, max_frame, &nodes, node.parent) / len);
                frame.splice(node.end..node.end, bytes.repeat(n));
                grow(&mut frame, &nodes, node.parent, (n * len) as isize);
            }
            // Move it to another place (not into itself).
            2 => {
                let all = slots(&nodes, frame.len());
                let to = all[usize::from(input.u16()) % all.len()];
                if ancestors(&nodes, to.parent).contains(&at)
                    || room_in(&frame, max_frame, &nodes, to.parent) < len
                {
                    continue;
                }
                frame.drain(node.start..node.end);
                grow(&mut frame, &nodes, node.parent, -(len as isize));
                // Positions after the removed parameter moved back by its length.
                let moved = |p: usize| if p >= node.end { p - len } else { p };
                let after: Vec<Node> = nodes
                    .iter()
                    .map(|n| Node {
                        start: moved(n.start),
                        end: moved(n.end),
                        ..*n
                    })
                    .collect();
                let pos = moved(to.pos);
                frame.splice(pos..pos, bytes);
                grow(&mut frame, &after, to.parent, len as isize);
            }
            // Copy it to another place.
            3 => {
                let all = slots(&nodes, frame.len());
                let to = all[usize::from(input.u16()) % all.len()];
                if room_in(&frame, max_frame, &nodes, to.parent) < len {
                    continue;
                }
                frame.splice(to.pos..to.pos, bytes);
                grow(&mut frame, &nodes, to.parent, len as isize);
            }
            // Drop it.
            _ => {
                frame.drain(node.start..node.end);
                grow(&mut frame, &nodes, node.parent, -(len as isize));
            }
        }
    }
    frame
}
