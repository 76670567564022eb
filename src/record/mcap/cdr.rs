//! A ROS 2 CDR encoder: the plain CDR (XCDR1) little-endian stream that ROS 2's middlewares
//! (Fast DDS, Cyclone DDS) put on the wire and rosbag2 stores, with its 4-byte encapsulation
//! header `00 01 00 00` (CDR_LE). Each primitive is aligned to its own size (at most 8),
//! counted from the first byte after the encapsulation header; a string is its length with the
//! terminating NUL (uint32), its bytes and the NUL; a sequence is its element count (uint32)
//! and the elements. This is all the message set of `ros2/llrp_gateway_msgs` needs (no arrays
//! of strings, no nested sequences). The unit tests compare the bytes with what Python's
//! `rosbags` serializer writes for the same messages.

/// The encapsulation header of a little-endian plain CDR payload (representation CDR_LE).
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// One message being encoded.
#[derive(Debug)]
pub struct Cdr {
    buf: Vec<u8>,
}

impl Default for Cdr {
    fn default() -> Self {
        Cdr::new()
    }
}

impl Cdr {
    /// An empty message: the encapsulation header only.
    pub fn new() -> Cdr {
        Cdr {
            buf: CDR_LE.to_vec(),
        }
    }

    /// Pads with zeros so the next value starts at a multiple of `n` bytes after the header.
    fn align(&mut self, n: usize) {
        let at = self.buf.len() - CDR_LE.len();
        let pad = (n - at % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// A `uint8` (or `byte`, `char`).
    pub fn u8(&mut self, v: u8) -> &mut Cdr {
        self.buf.push(v);
        self
    }

    /// A `bool`: one byte, 0 or 1.
    pub fn bool(&mut self, v: bool) -> &mut Cdr {
        self.u8(u8::from(v))
    }

    /// A `uint16`.
    pub fn u16(&mut self, v: u16) -> &mut Cdr {
        self.align(2);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `uint32`.
    pub fn u32(&mut self, v: u32) -> &mut Cdr {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) -> &mut Cdr {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `uint64`.
    pub fn u64(&mut self, v: u64) -> &mut Cdr {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) -> &mut Cdr {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `string`: length with the NUL, the UTF-8 bytes, the NUL.
    pub fn string(&mut self, s: &str) -> &mut Cdr {
        self.u32(sequence_len(s.len() + 1));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        self
    }

    /// A `uint8[]`: the count, then the bytes.
    pub fn bytes(&mut self, b: &[u8]) -> &mut Cdr {
        self.u32(sequence_len(b.len()));
        self.buf.extend_from_slice(b);
        self
    }

    /// A `builtin_interfaces/Time` from UTC nanoseconds since the Unix epoch (`sec` is an
    /// `int32`: a time past 2038-01-19T03:14:07Z is written as that second).
    pub fn time(&mut self, utc_ns: u64) -> &mut Cdr {
        let (sec, nanosec) = ros_time(utc_ns);
        self.i32(sec).u32(nanosec)
    }

    /// A `std_msgs/Header`: the stamp (UTC ns) and the frame id.
    pub fn header(&mut self, utc_ns: u64, frame_id: &str) -> &mut Cdr {
        self.time(utc_ns).string(frame_id)
    }

    /// The encoded message, header included.
    pub fn finish(&mut self) -> Vec<u8> {
        std::mem::replace(&mut self.buf, CDR_LE.to_vec())
    }
}

/// A length as CDR's uint32 (a frame or a string of llrp-gateway is far below 4 GiB: LLRP's
/// length field is itself 32 bits; longer ones are cut to the largest count, which a reader
/// then refuses rather than misreads).
fn sequence_len(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// `builtin_interfaces/Time`'s `(sec, nanosec)` of UTC nanoseconds (sec saturated at
/// `i32::MAX`).
pub fn ros_time(utc_ns: u64) -> (i32, u32) {
    let sec = i32::try_from(utc_ns / 1_000_000_000).unwrap_or(i32::MAX);
    // The remainder of a division by 10^9 is below 10^9, so it fits a u32.
    let nanosec = (utc_ns % 1_000_000_000) as u32;
    (sec, nanosec)
}

#[cfg(test)]
#[path = "cdr_tests.rs"]
mod tests;
