//! A tag's EPC as every layer names it: hex digits in upper case. The case rule is here and
//! nowhere else: any case in (a reads file, a URL, a settings file, a broker's message),
//! upper case out, so that two spellings of one EPC are one tag.

use std::borrow::Borrow;
use std::fmt;
use std::ops::Deref;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize};

/// A tag's EPC: an even number of hex digits, upper case (the bytes of the EPC bank's EPC as
/// a reader reports them).
#[derive(Clone, Default, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(transparent)]
pub struct Epc(String);

/// Why a text is no EPC.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EpcError {
    /// Nothing was given.
    #[error("the EPC is empty")]
    Empty,
    /// A character is no hex digit.
    #[error("EPC {text:?} is not hex: {found:?} at offset {offset} is no hex digit")]
    NotHex {
        /// The text given.
        text: String,
        /// The first character that is no hex digit.
        found: char,
        /// Its byte offset.
        offset: usize,
    },
    /// An odd number of digits: no whole bytes.
    #[error("EPC {text:?} is not hex bytes: an odd number of digits ({digits})")]
    OddDigits {
        /// The text given.
        text: String,
        /// How many digits it has.
        digits: usize,
    },
}

impl Epc {
    /// The EPC `text` names, in any case; an error says why it names none.
    pub fn parse(text: &str) -> Result<Epc, EpcError> {
        if text.is_empty() {
            return Err(EpcError::Empty);
        }
        if let Some((offset, found)) = text.char_indices().find(|(_, c)| !c.is_ascii_hexdigit()) {
            return Err(EpcError::NotHex {
                text: text.to_string(),
                found,
                offset,
            });
        }
        if !text.len().is_multiple_of(2) {
            return Err(EpcError::OddDigits {
                text: text.to_string(),
                digits: text.len(),
            });
        }
        Ok(Epc(text.to_ascii_uppercase()))
    }

    /// The EPC of these bytes, as a reader reports them (any length, none included).
    pub fn from_bytes(bytes: &[u8]) -> Epc {
        const DIGITS: &[u8; 16] = b"0123456789ABCDEF";
        let mut s = String::with_capacity(bytes.len() * 2);
        for &b in bytes {
            s.push(char::from(DIGITS[usize::from(b >> 4)]));
            s.push(char::from(DIGITS[usize::from(b & 0x0f)]));
        }
        Epc(s)
    }

    /// The EPC of the first `bits` bits of `bytes` (an EPCData's bit string, e.g. a truncated
    /// EPC): its ceil(bits / 8) bytes in hex, the bits past `bits` in the last byte cleared.
    /// So a 76-bit EPC shows as 10 bytes, its last 4 bits 0: the bit count is not shown.
    pub fn from_bits(bytes: &[u8], bits: u16) -> Epc {
        let n = usize::from(bits).div_ceil(8).min(bytes.len());
        let mut head = bytes[..n].to_vec();
        let spare = n * 8 - usize::from(bits).min(n * 8);
        if let Some(last) = head.last_mut() {
            *last &= 0xFFu8 << spare;
        }
        Epc::from_bytes(&head)
    }

    /// The EPC as upper-case hex.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The EPC as upper-case hex, owned.
    pub fn into_string(self) -> String {
        self.0
    }
}

impl FromStr for Epc {
    type Err = EpcError;

    fn from_str(s: &str) -> Result<Epc, EpcError> {
        Epc::parse(s)
    }
}

impl<'de> Deserialize<'de> for Epc {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Epc, D::Error> {
        let text = std::borrow::Cow::<str>::deserialize(d)?;
        Epc::parse(&text).map_err(serde::de::Error::custom)
    }
}

impl Deref for Epc {
    type Target = str;

    fn deref(&self) -> &str {
        &self.0
    }
}

impl AsRef<str> for Epc {
    fn as_ref(&self) -> &str {
        &self.0
    }
}

impl Borrow<str> for Epc {
    fn borrow(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for Epc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl fmt::Debug for Epc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl PartialEq<str> for Epc {
    fn eq(&self, other: &str) -> bool {
        self.0 == other
    }
}

impl PartialEq<&str> for Epc {
    fn eq(&self, other: &&str) -> bool {
        self.0 == *other
    }
}

impl PartialEq<String> for Epc {
    fn eq(&self, other: &String) -> bool {
        &self.0 == other
    }
}

impl From<Epc> for String {
    fn from(e: Epc) -> String {
        e.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn any_case_in_is_one_epc_in_upper_case_out() {
        let a = Epc::parse("e2801160600002").expect("hex");
        let b = Epc::parse("E2801160600002").expect("hex");
        assert_eq!(a, b);
        assert_eq!(a.as_str(), "E2801160600002");
        assert_eq!(
            a,
            Epc::from_bytes(&[0xE2, 0x80, 0x11, 0x60, 0x60, 0x00, 0x02])
        );
        let json: Epc = serde_json::from_str("\"abcd\"").expect("an EPC");
        assert_eq!(json, "ABCD");
        assert_eq!(serde_json::to_string(&json).expect("text"), "\"ABCD\"");
    }

    #[test]
    fn a_text_that_is_no_epc_is_told_why() {
        assert_eq!(Epc::parse(""), Err(EpcError::Empty));
        assert!(matches!(
            Epc::parse("12G4"),
            Err(EpcError::NotHex {
                found: 'G',
                offset: 2,
                ..
            })
        ));
        assert!(matches!(
            Epc::parse("ABC"),
            Err(EpcError::OddDigits { digits: 3, .. })
        ));
        let e = serde_json::from_str::<Epc>("\"ABC\"").expect_err("odd");
        assert!(e.to_string().contains("odd number of digits"), "{e}");
    }
}
