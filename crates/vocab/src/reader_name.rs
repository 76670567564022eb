//! A reader's name as every layer names it: the scenario's readers, the proxies of a gateway
//! configuration, the inventory client's `--name`, the reads and pose samples that carry it,
//! the feed, the localizer's tracks, the API and the broker's messages. The rule is here and
//! nowhere else: not empty, no white space at either end, no control character, at most
//! [`MAX_LEN`] bytes. Case is kept and names are compared exactly (`Reader-1` and `reader-1`
//! are two readers), as they always were.

use std::borrow::Borrow;
use std::fmt;
use std::ops::Deref;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Longest reader name, in bytes (UTF-8): room for any `host:port` an inventory client
/// names its reader by.
pub const MAX_LEN: usize = 256;

/// A reader's name: not empty, no white space at either end, no control character, at most
/// [`MAX_LEN`] bytes; case kept.
#[derive(Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(transparent)]
pub struct ReaderName(String);

/// Why a text is no reader name.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ReaderNameError {
    /// Nothing was given.
    #[error("the reader name is empty")]
    Empty,
    /// It starts or ends with white space.
    #[error("reader name {text:?} starts or ends with white space")]
    Spaces {
        /// The text given.
        text: String,
    },
    /// It holds a control character (a line end, a tab, NUL, ...).
    #[error("reader name {text:?} holds a control character ({found:?} at offset {offset})")]
    Control {
        /// The text given.
        text: String,
        /// The first control character.
        found: char,
        /// Its byte offset.
        offset: usize,
    },
    /// It is longer than [`MAX_LEN`] bytes.
    #[error("the reader name is {len} bytes long, more than the {MAX_LEN} allowed")]
    TooLong {
        /// Its length in bytes.
        len: usize,
    },
}

impl ReaderName {
    /// The reader name `text` is, as it is; an error says why it is none.
    pub fn parse(text: &str) -> Result<ReaderName, ReaderNameError> {
        check(text)?;
        Ok(ReaderName(text.to_owned()))
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The name, owned.
    pub fn into_string(self) -> String {
        self.0
    }
}

/// Why `text` breaks the rule, if it does.
fn check(text: &str) -> Result<(), ReaderNameError> {
    if text.is_empty() {
        return Err(ReaderNameError::Empty);
    }
    if text.len() > MAX_LEN {
        return Err(ReaderNameError::TooLong { len: text.len() });
    }
    if let Some((offset, found)) = text.char_indices().find(|(_, c)| c.is_control()) {
        return Err(ReaderNameError::Control {
            text: text.to_owned(),
            found,
            offset,
        });
    }
    if text.trim() != text {
        return Err(ReaderNameError::Spaces {
            text: text.to_owned(),
        });
    }
    Ok(())
}

impl TryFrom<String> for ReaderName {
    type Error = ReaderNameError;

    /// The reader name `text` is, without a copy.
    fn try_from(text: String) -> Result<ReaderName, ReaderNameError> {
        check(&text)?;
        Ok(ReaderName(text))
    }
}

impl FromStr for ReaderName {
    type Err = ReaderNameError;

    fn from_str(s: &str) -> Result<ReaderName, ReaderNameError> {
        ReaderName::parse(s)
    }
}

impl<'de> Deserialize<'de> for ReaderName {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<ReaderName, D::Error> {
        let text = std::borrow::Cow::<str>::deserialize(d)?;
        ReaderName::parse(&text).map_err(serde::de::Error::custom)
    }
}

/// Deserializes an optional reader name where the empty text means none (the pose file's
/// `reader`, which an unnamed reader's poses leave empty or out: give the field
/// `#[serde(default)]` too).
pub fn empty_is_none<'de, D: Deserializer<'de>>(d: D) -> Result<Option<ReaderName>, D::Error> {
    let text = std::borrow::Cow::<str>::deserialize(d)?;
    if text.is_empty() {
        return Ok(None);
    }
    ReaderName::parse(&text)
        .map(Some)
        .map_err(serde::de::Error::custom)
}

/// Serializes an optional reader name as the empty text when there is none (the inverse of
/// [`empty_is_none`]).
pub fn none_as_empty<S: Serializer>(name: &Option<ReaderName>, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(name.as_deref().unwrap_or_default())
}

impl Deref for ReaderName {
    type Target = str;

    fn deref(&self) -> &str {
        &self.0
    }
}

impl AsRef<str> for ReaderName {
    fn as_ref(&self) -> &str {
        &self.0
    }
}

impl Borrow<str> for ReaderName {
    fn borrow(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for ReaderName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl fmt::Debug for ReaderName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl PartialEq<str> for ReaderName {
    fn eq(&self, other: &str) -> bool {
        self.0 == other
    }
}

impl PartialEq<&str> for ReaderName {
    fn eq(&self, other: &&str) -> bool {
        self.0 == *other
    }
}

impl PartialEq<String> for ReaderName {
    fn eq(&self, other: &String) -> bool {
        &self.0 == other
    }
}

impl From<ReaderName> for String {
    fn from(r: ReaderName) -> String {
        r.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_name_is_kept_as_given_and_compared_exactly() {
        for text in [
            "sim-0",
            "Reader 1",
            "192.168.1.20:5084",
            "dock/left",
            "Lesegerät",
        ] {
            let name = ReaderName::parse(text).expect("a name");
            assert_eq!(name, text);
            assert_eq!(name.to_string(), text);
        }
        assert_ne!(
            ReaderName::parse("Reader").expect("a name"),
            ReaderName::parse("reader").expect("a name")
        );
        let json: ReaderName = serde_json::from_str("\"r1\"").expect("a name");
        assert_eq!(serde_json::to_string(&json).expect("text"), "\"r1\"");
        assert!(ReaderName::parse(&"r".repeat(MAX_LEN)).is_ok());
    }

    #[test]
    fn a_text_that_is_no_name_is_told_why() {
        assert_eq!(ReaderName::parse(""), Err(ReaderNameError::Empty));
        for text in [" r", "r ", " ", "r\u{a0}"] {
            assert!(
                matches!(ReaderName::parse(text), Err(ReaderNameError::Spaces { .. })),
                "{text:?}"
            );
        }
        assert!(matches!(
            ReaderName::parse("r\n1"),
            Err(ReaderNameError::Control {
                found: '\n',
                offset: 1,
                ..
            })
        ));
        assert!(matches!(
            ReaderName::parse("r\u{0}"),
            Err(ReaderNameError::Control { .. })
        ));
        assert_eq!(
            ReaderName::parse(&"r".repeat(MAX_LEN + 1)),
            Err(ReaderNameError::TooLong { len: MAX_LEN + 1 })
        );
        assert_eq!(
            ReaderName::try_from(String::from("\tr")),
            Err(ReaderNameError::Control {
                text: "\tr".into(),
                found: '\t',
                offset: 0
            })
        );
        let e = serde_json::from_str::<ReaderName>("\" r\"").expect_err("spaces");
        assert!(e.to_string().contains("white space"), "{e}");
    }

    #[test]
    fn an_empty_optional_name_is_none() {
        #[derive(Deserialize, Serialize)]
        struct Row {
            #[serde(
                default,
                deserialize_with = "empty_is_none",
                serialize_with = "none_as_empty"
            )]
            reader: Option<ReaderName>,
        }
        let text = |reader| serde_json::to_string(&Row { reader }).expect("text");
        assert_eq!(text(None), r#"{"reader":""}"#);
        assert_eq!(text("r".parse().ok()), r#"{"reader":"r"}"#);
        let row = |json: &str| serde_json::from_str::<Row>(json).map(|r| r.reader);
        assert_eq!(row("{}").expect("absent"), None);
        assert_eq!(row(r#"{"reader":""}"#).expect("empty"), None);
        assert!(row(r#"{"reader":null}"#).is_err(), "a string or nothing");
        assert_eq!(
            row(r#"{"reader":"r"}"#).expect("a name"),
            Some(ReaderName::parse("r").expect("a name"))
        );
        assert!(row(r#"{"reader":" "}"#).is_err());
    }
}
