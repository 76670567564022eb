//! A ROS 2 CDR decoder: the reverse of [`super::cdr`], for the messages `localize` and
//! `replay` take out of MCAP files (`geometry_msgs`, `nav_msgs`, `tf2_msgs` and
//! `llrp_gateway_msgs`). Plain CDR (XCDR1, OMG DDS-XTypes 1.3 §7.4.3.5) after its 4-byte
//! encapsulation header: `00 01` little-endian (what ROS 2's middlewares write) or `00 00`
//! big-endian; each primitive aligned to its own size (at most 8) from the first byte after
//! the header; a string its length with the NUL (uint32), its bytes and the NUL; a sequence
//! its count (uint32) and its elements. The unit tests read bytes Python's `rosbags` wrote.

/// Why a CDR message could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    /// The encapsulation header is not plain CDR (little- or big-endian).
    #[error("not a plain CDR message (encapsulation {0:02x?})")]
    Encapsulation(Vec<u8>),
    /// The message ends before a value it must hold.
    #[error("the message ends at byte {at}, inside a value of {needed} bytes")]
    Short {
        /// Where the value starts (after the encapsulation header).
        at: usize,
        /// The value's length.
        needed: usize,
    },
    /// A string is not UTF-8, or lacks its NUL.
    #[error("a string at byte {0} is not NUL-terminated UTF-8")]
    BadString(usize),
}

/// A message being decoded.
#[derive(Debug)]
pub struct CdrReader<'a> {
    /// The message after the encapsulation header.
    body: &'a [u8],
    /// The next byte to read in `body`.
    at: usize,
    /// Little-endian (else big-endian).
    little: bool,
}

impl<'a> CdrReader<'a> {
    /// A reader of `data`, a message with its encapsulation header.
    pub fn new(data: &'a [u8]) -> Result<CdrReader<'a>, CdrError> {
        let little = match data.get(..2) {
            Some([0, 1]) => true,
            Some([0, 0]) => false,
            _ => return Err(CdrError::Encapsulation(data[..data.len().min(4)].to_vec())),
        };
        let body = data.get(4..).ok_or(CdrError::Short { at: 0, needed: 4 })?;
        Ok(CdrReader {
            body,
            at: 0,
            little,
        })
    }

    /// The next `N` bytes, aligned to `N` (at most 8).
    fn take<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        let align = N.min(8);
        self.at += (align - self.at % align) % align;
        let bytes = self.raw(N)?;
        let mut out = [0; N];
        out.copy_from_slice(bytes);
        if !self.little {
            out.reverse();
        }
        Ok(out)
    }

    /// The next `n` bytes as they are, unaligned.
    fn raw(&mut self, n: usize) -> Result<&'a [u8], CdrError> {
        let short = CdrError::Short {
            at: self.at,
            needed: n,
        };
        let end = self.at.checked_add(n).ok_or(short.clone())?;
        let bytes = self.body.get(self.at..end).ok_or(short)?;
        self.at = end;
        Ok(bytes)
    }

    /// A `uint8` (or `byte`, `char`).
    pub fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(self.take::<1>()?[0])
    }

    /// A `bool` (any byte but 0 is true).
    pub fn bool(&mut self) -> Result<bool, CdrError> {
        Ok(self.u8()? != 0)
    }

    /// A `uint16`.
    pub fn u16(&mut self) -> Result<u16, CdrError> {
        Ok(u16::from_le_bytes(self.take()?))
    }

    /// A `uint32`.
    pub fn u32(&mut self) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.take()?))
    }

    /// An `int32`.
    pub fn i32(&mut self) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.take()?))
    }

    /// A `uint64`.
    pub fn u64(&mut self) -> Result<u64, CdrError> {
        Ok(u64::from_le_bytes(self.take()?))
    }

    /// A `float64`.
    pub fn f64(&mut self) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.take()?))
    }

    /// `n` `float64`s (a fixed-size array, e.g. a covariance).
    pub fn f64s(&mut self, n: usize) -> Result<Vec<f64>, CdrError> {
        (0..n).map(|_| self.f64()).collect()
    }

    /// A `string`.
    pub fn string(&mut self) -> Result<String, CdrError> {
        let len = self.u32()? as usize;
        let at = self.at;
        let bytes = self.raw(len)?;
        match bytes.split_last() {
            Some((0, text)) => std::str::from_utf8(text)
                .map(str::to_owned)
                .map_err(|_| CdrError::BadString(at)),
            // An empty string written without its NUL (some writers do).
            None => Ok(String::new()),
            Some(_) => Err(CdrError::BadString(at)),
        }
    }

    /// A `uint8[]`.
    pub fn bytes(&mut self) -> Result<Vec<u8>, CdrError> {
        let len = self.u32()? as usize;
        Ok(self.raw(len)?.to_vec())
    }

    /// A sequence's element count.
    pub fn count(&mut self) -> Result<usize, CdrError> {
        Ok(self.u32()? as usize)
    }

    /// A `builtin_interfaces/Time` as nanoseconds since its epoch (negative before it).
    pub fn time(&mut self) -> Result<i64, CdrError> {
        let sec = self.i32()?;
        let nanosec = self.u32()?;
        Ok(i64::from(sec) * 1_000_000_000 + i64::from(nanosec))
    }

    /// A `std_msgs/Header`: the stamp (ns, as [`CdrReader::time`]) and the frame id.
    pub fn header(&mut self) -> Result<(i64, String), CdrError> {
        Ok((self.time()?, self.string()?))
    }
}

#[cfg(test)]
#[path = "cdr_read_tests.rs"]
mod tests;
