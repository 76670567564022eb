//! The lossless generic form: parameters the codec does not type, kept as their exact bytes.

use crate::codec::{ParamHeader, CUSTOM_TYPE};

/// A whole encoded parameter (header included), kept byte for byte.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct RawParam {
    /// The parameter's bytes, header included.
    pub bytes: Vec<u8>,
}

impl RawParam {
    /// Wraps the bytes of one whole parameter.
    pub fn new(bytes: Vec<u8>) -> Self {
        RawParam { bytes }
    }

    /// The parameter's header, if the bytes hold a valid one.
    pub fn header(&self) -> Option<ParamHeader> {
        if self.bytes.is_empty() {
            return None;
        }
        ParamHeader::read(&self.bytes).ok()
    }

    /// TLV (or TV) type number, or 0 if the bytes are not a parameter.
    pub fn param_type(&self) -> u16 {
        self.header().map_or(0, |h| h.ty())
    }

    /// Vendor and subtype, for a Custom parameter.
    pub fn vendor_subtype(&self) -> Option<(u32, u32)> {
        self.header()
            .filter(|h| !h.tv() && h.ty() == CUSTOM_TYPE)
            .map(|h| (h.vendor(), h.subtype()))
    }
}

/// A parameter the codec set aside, with its position among its container's sub-parameters.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Extra {
    /// Number of typed sub-parameters that precede it in its container.
    pub at: u32,
    /// The parameter itself.
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub param: RawParam,
}

/// Lower-case hex of `bytes`.
pub fn to_hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        s.push(DIGITS[usize::from(b >> 4)] as char);
        s.push(DIGITS[usize::from(b & 0xF)] as char);
    }
    s
}

/// Bytes from hex text; whitespace is ignored.
pub fn from_hex(text: &str) -> Result<Vec<u8>, HexError> {
    let digits: Vec<u8> = text.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
    if !digits.len().is_multiple_of(2) {
        return Err(HexError::OddLength);
    }
    digits
        .chunks_exact(2)
        .enumerate()
        .map(|(n, pair)| {
            let hi = (pair[0] as char).to_digit(16);
            let lo = (pair[1] as char).to_digit(16);
            match (hi, lo) {
                (Some(h), Some(l)) => Ok((h * 16 + l) as u8),
                _ => Err(HexError::BadDigit { pos: n * 2 }),
            }
        })
        .collect()
}

/// Why hex text could not be read.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum HexError {
    /// An odd number of hex digits.
    #[error("odd number of hex digits")]
    OddLength,
    /// A character that is not a hex digit.
    #[error("not a hex digit near digit {pos}")]
    BadDigit {
        /// Index of the digit pair among the digits.
        pos: usize,
    },
}

#[cfg(feature = "serde")]
mod serde_impl {
    use super::*;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    struct RawView {
        #[serde(rename = "type", default)]
        ty: u16,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        vendor: Option<u32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        subtype: Option<u32>,
        hex: String,
    }

    impl Serialize for RawParam {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            let vs = self.vendor_subtype();
            RawView {
                ty: self.param_type(),
                vendor: vs.map(|v| v.0),
                subtype: vs.map(|v| v.1),
                hex: to_hex(&self.bytes),
            }
            .serialize(s)
        }
    }

    impl<'de> Deserialize<'de> for RawParam {
        fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            let v = RawView::deserialize(d)?;
            from_hex(&v.hex)
                .map(RawParam::new)
                .map_err(serde::de::Error::custom)
        }
    }

    /// Serde helper: bytes as a hex string.
    pub mod hex_bytes {
        use super::*;

        /// Serializes bytes as hex.
        pub fn serialize<S: Serializer, B: AsRef<[u8]>>(b: &B, s: S) -> Result<S::Ok, S::Error> {
            s.serialize_str(&to_hex(b.as_ref()))
        }

        /// Deserializes hex into bytes of the right form.
        pub fn deserialize<'de, D: Deserializer<'de>, B: TryFrom<Vec<u8>>>(
            d: D,
        ) -> Result<B, D::Error> {
            let s = String::deserialize(d)?;
            let v = from_hex(&s).map_err(serde::de::Error::custom)?;
            B::try_from(v).map_err(|_| serde::de::Error::custom("wrong number of bytes"))
        }
    }

    impl Serialize for crate::codec::BitVec {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            if usize::from(self.bits) == self.bytes.len() * 8 {
                s.serialize_str(&to_hex(&self.bytes))
            } else {
                #[derive(Serialize)]
                struct View {
                    bits: u16,
                    hex: String,
                }
                View {
                    bits: self.bits,
                    hex: to_hex(&self.bytes),
                }
                .serialize(s)
            }
        }
    }

    impl<'de> Deserialize<'de> for crate::codec::BitVec {
        fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            #[derive(Deserialize)]
            #[serde(untagged)]
            enum View {
                Hex(String),
                Bits { bits: u16, hex: String },
            }
            let (bits, hex) = match View::deserialize(d)? {
                View::Hex(h) => (None, h),
                View::Bits { bits, hex } => (Some(bits), hex),
            };
            let bytes = from_hex(&hex).map_err(serde::de::Error::custom)?;
            let bits = match bits {
                Some(b) => b,
                None => u16::try_from(bytes.len() * 8).map_err(serde::de::Error::custom)?,
            };
            Ok(crate::codec::BitVec { bits, bytes })
        }
    }
}

#[cfg(feature = "serde")]
pub use serde_impl::hex_bytes;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_round_trip_ignores_whitespace() {
        assert_eq!(from_hex("04 3e\n00").unwrap(), vec![0x04, 0x3e, 0x00]);
        assert_eq!(to_hex(&[0x04, 0x3e, 0xff]), "043eff");
        assert_eq!(from_hex("043"), Err(HexError::OddLength));
        assert!(matches!(from_hex("zz"), Err(HexError::BadDigit { .. })));
    }

    #[test]
    fn raw_param_reports_custom_vendor() {
        let p = RawParam::new(vec![0x03, 0xFF, 0, 12, 0, 0, 0x65, 0x1A, 0, 0, 0, 56]);
        assert_eq!(p.param_type(), 1023);
        assert_eq!(p.vendor_subtype(), Some((25882, 56)));
    }
}
