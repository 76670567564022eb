//! Tag memory banks from their scenario strings: the EPC, TID and user memory.

use std::fmt;
use std::hash::{Hash, Hasher};

/// Most 16-bit words a Gen2 EPC can have: the PC word's EPC length field has 5 bits.
pub const MAX_EPC_WORDS: usize = 31;

/// A tag's EPC: a whole number of 16-bit words, 1 to [`MAX_EPC_WORDS`] (16–496 bits).
///
/// Stored inline (63 bytes) and `Copy`, rather than as a `Box<[u8]>` or an `Arc<[u8]>` shared
/// per tag: every tag read copies its tag's EPC into an observation and, for an EPC-96, into
/// its report, and at over a million reads a second a 63-byte copy costs less than an
/// allocation or an atomic reference count per read. Bytes past the length are always zero.
#[derive(Clone, Copy)]
pub struct TagEpc {
    /// Length in bytes (even, 2..=62).
    len: u8,
    /// The EPC, most significant byte first, zero-padded.
    bytes: [u8; 2 * MAX_EPC_WORDS],
}

impl TagEpc {
    /// The EPC of `bytes`, which must be 1 to 31 whole 16-bit words.
    pub fn from_bytes(bytes: &[u8]) -> Result<TagEpc, String> {
        if bytes.is_empty() {
            return Err(format!(
                "must not be empty (1 to {MAX_EPC_WORDS} 16-bit words of 4 hex digits)"
            ));
        }
        if !bytes.len().is_multiple_of(2) {
            return Err(format!(
                "must be whole 16-bit words, got {} bytes",
                bytes.len()
            ));
        }
        if bytes.len() > 2 * MAX_EPC_WORDS {
            return Err(format!(
                "must be at most {MAX_EPC_WORDS} 16-bit words ({} bits), got {} words",
                16 * MAX_EPC_WORDS,
                bytes.len() / 2
            ));
        }
        let mut epc = TagEpc {
            // At most 62 (checked above), so the cast is lossless.
            len: bytes.len() as u8,
            bytes: [0; 2 * MAX_EPC_WORDS],
        };
        epc.bytes[..bytes.len()].copy_from_slice(bytes);
        Ok(epc)
    }

    /// The EPC's bytes, most significant first.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..usize::from(self.len)]
    }

    /// The EPC's bytes followed by zeros, as stored: fixed offsets for code that packs short
    /// EPCs into words.
    pub fn padded(&self) -> &[u8; 2 * MAX_EPC_WORDS] {
        &self.bytes
    }

    /// Length in 16-bit words (1..=31).
    pub fn words(&self) -> usize {
        usize::from(self.len) / 2
    }

    /// Length in bits (16..=496).
    pub fn bits(&self) -> u16 {
        u16::from(self.len) * 8
    }

    /// The EPC-96 bytes, if the EPC is 96 bits long.
    pub fn as_epc96(&self) -> Option<[u8; 12]> {
        <[u8; 12]>::try_from(self.as_bytes()).ok()
    }

    /// The tag's PC word: the EPC length in words in bits 15–11 (Gen2), no user memory
    /// indicator, no XPC, GS1 numbering (0x3000 for an EPC-96).
    pub fn pc(&self) -> u16 {
        // words() ≤ 31 fits the 5-bit field.
        (self.words() as u16) << 11
    }
}

impl From<[u8; 12]> for TagEpc {
    /// An EPC-96.
    fn from(bytes: [u8; 12]) -> TagEpc {
        let mut epc = TagEpc {
            len: 12,
            bytes: [0; 2 * MAX_EPC_WORDS],
        };
        epc.bytes[..12].copy_from_slice(&bytes);
        epc
    }
}

impl PartialEq for TagEpc {
    fn eq(&self, other: &TagEpc) -> bool {
        self.as_bytes() == other.as_bytes()
    }
}

impl Eq for TagEpc {}

impl Hash for TagEpc {
    fn hash<H: Hasher>(&self, state: &mut H) {
        self.as_bytes().hash(state);
    }
}

impl fmt::Debug for TagEpc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("TagEpc(")?;
        for b in self.as_bytes() {
            write!(f, "{b:02X}")?;
        }
        f.write_str(")")
    }
}

/// Parses an EPC given as hex digits: 1 to 31 whole 16-bit words (4 to 124 digits).
pub fn parse_epc(hex: &str) -> Result<TagEpc, String> {
    let words = parse_words(hex)?;
    let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_be_bytes()).collect();
    TagEpc::from_bytes(&bytes)
}

/// Words of user memory a tag has when its scenario gives none: 512 bits of zeros, the user
/// memory of Impinj's Monza 4QT (Monza 4 Tag Chip Datasheet, memory map).
pub const DEFAULT_USER_WORDS: usize = 32;

/// User memory of a tag whose scenario gives none ([`DEFAULT_USER_WORDS`] zero words).
pub fn default_user() -> Vec<u16> {
    vec![0; DEFAULT_USER_WORDS]
}

/// Parses a 32-bit password given as exactly 8 hex digits.
pub fn parse_password(hex: &str) -> Result<u32, String> {
    if hex.len() != 8 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(format!("must be 8 hex digits (32 bits), got {hex:?}"));
    }
    u32::from_str_radix(hex, 16).map_err(|e| e.to_string())
}

/// Parses memory given as hex digits, a whole number of 16-bit words (4 digits each).
pub fn parse_words(hex: &str) -> Result<Vec<u16>, String> {
    if !hex.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(format!("must be hex digits, got \"{hex}\""));
    }
    if !hex.len().is_multiple_of(4) {
        return Err(format!(
            "must be whole 16-bit words (a multiple of 4 hex digits), got {} digits",
            hex.len()
        ));
    }
    (0..hex.len() / 4)
        .map(|i| {
            u16::from_str_radix(&hex[4 * i..4 * i + 4], 16)
                .map_err(|_| format!("must be hex digits, got \"{hex}\""))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epc_and_words_parse() {
        let epc = parse_epc("300833B2DDD9014000000001").expect("valid EPC");
        assert_eq!(epc.as_bytes()[0], 0x30);
        assert_eq!(epc.as_bytes()[11], 0x01);
        assert!(parse_epc("300833B2DDD90140000000").is_err());
        assert!(parse_epc("300833B2DDD901400000000G").is_err());
        assert!(parse_epc("300833B2DDD9014000000é1").is_err());
        assert_eq!(
            parse_words("E2801160ABCD"),
            Ok(vec![0xE280, 0x1160, 0xABCD])
        );
        assert_eq!(parse_words(""), Ok(vec![]));
        assert!(parse_words("E28").is_err());
        assert!(parse_words("E28X").is_err());
    }

    #[test]
    fn epcs_of_one_to_31_words_parse_with_their_length_and_pc() {
        for words in 1..=MAX_EPC_WORDS {
            let hex: String = (0..words).map(|i| format!("{:04X}", 0xA000 + i)).collect();
            let epc = parse_epc(&hex).expect("1 to 31 words");
            assert_eq!(epc.words(), words);
            assert_eq!(usize::from(epc.bits()), 16 * words);
            assert_eq!(epc.as_bytes().len(), 2 * words);
            assert_eq!(usize::from(epc.pc() >> 11), words);
            assert_eq!(epc.pc() & 0x07FF, 0);
            assert_eq!(epc.as_bytes()[2 * words - 1], words as u8 - 1);
        }
        let e96 = parse_epc("300833B2DDD9014000000001").expect("valid EPC");
        assert_eq!(e96.pc(), 0x3000);
        assert_eq!(e96, TagEpc::from(e96.as_epc96().expect("96 bits")));
        let e128 = parse_epc("E2801160600002093F4A3B1C00000001").expect("valid EPC");
        assert_eq!(
            (e128.bits(), e128.pc(), e128.as_epc96()),
            (128, 0x4000, None)
        );
    }

    #[test]
    fn epc_errors_name_the_reason() {
        assert_eq!(
            parse_epc(""),
            Err("must not be empty (1 to 31 16-bit words of 4 hex digits)".into())
        );
        assert_eq!(
            parse_epc("300833B2DDD90140000000"),
            Err("must be whole 16-bit words (a multiple of 4 hex digits), got 22 digits".into())
        );
        assert_eq!(
            parse_epc(&"ABCD".repeat(32)),
            Err("must be at most 31 16-bit words (496 bits), got 32 words".into())
        );
        assert_eq!(
            parse_epc("30083G"),
            Err("must be hex digits, got \"30083G\"".into())
        );
        // Equal prefixes of different lengths are different EPCs.
        assert_ne!(parse_epc("3000"), parse_epc("30000000"));
    }
}
