//! Secrets the commands are given (the HTTP API's bearer token, the MQTT broker's password):
//! [`Secret`], whose `Debug` and `Display` print `***` so that no log line, error or `{:?}` of
//! an options struct shows one, and the reading of one from a file (`--http-token-file`,
//! `--mqtt-password-file`), which keeps it out of the process list. A module of its own at
//! the application's bottom, because the HTTP API (the token) and MQTT (the password) may not
//! name each other (ARCHITECTURE.md).

use std::fmt;
use std::path::Path;

/// A secret's text; shown as `***`. Only [`expose`](Secret::expose) gives the value, for the
/// one place that needs it (the token's comparison, the MQTT login).
#[derive(Clone, PartialEq, Eq)]
pub struct Secret(String);

impl Secret {
    /// A secret of `value`.
    pub fn new(value: impl Into<String>) -> Secret {
        Secret(value.into())
    }

    /// The value itself: never to be logged.
    pub fn expose(&self) -> &str {
        &self.0
    }

    /// Whether the value is empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The secret in the file at `path`: its text without the line ends at its end (`echo
    /// TOKEN > FILE` writes one); an empty file, or one of line ends only, is an error, as is
    /// one that cannot be read or is not UTF-8.
    pub fn from_file(path: &Path) -> Result<Secret, SecretFileError> {
        let text = std::fs::read_to_string(path).map_err(SecretFileError::Read)?;
        let value = text.trim_end_matches(['\r', '\n']);
        if value.is_empty() {
            return Err(SecretFileError::Empty);
        }
        Ok(Secret(value.to_owned()))
    }
}

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("***")
    }
}

impl fmt::Display for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("***")
    }
}

impl From<String> for Secret {
    fn from(value: String) -> Secret {
        Secret(value)
    }
}

impl From<&str> for Secret {
    fn from(value: &str) -> Secret {
        Secret(value.to_owned())
    }
}

/// Why a secret's file gave no secret.
#[derive(Debug, thiserror::Error)]
pub enum SecretFileError {
    /// The file could not be read (missing, no permission, not UTF-8).
    #[error("cannot read it: {0}")]
    Read(std::io::Error),
    /// The file holds nothing but line ends.
    #[error("it is empty")]
    Empty,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_secret_shows_as_stars_in_debug_display_and_the_structs_around_it() {
        #[derive(Debug)]
        #[allow(dead_code)]
        struct Options {
            token: Option<Secret>,
        }
        let s = Secret::new("hunter2");
        assert_eq!(format!("{s} {s:?} {s:#?}"), "*** *** ***");
        let o = Options {
            token: Some(s.clone()),
        };
        assert!(!format!("{o:?} {o:#?}").contains("hunter2"));
        assert_eq!(s.expose(), "hunter2");
    }

    #[test]
    fn a_file_gives_its_text_without_the_line_end_and_an_empty_one_is_refused() {
        let dir = tempfile::tempdir().expect("temp dir");
        let file = |name: &str, text: &str| {
            let p = dir.path().join(name);
            std::fs::write(&p, text).expect("writes");
            p
        };
        let s = Secret::from_file(&file("a", "p@ss word\n")).expect("read");
        assert_eq!(s.expose(), "p@ss word");
        let s = Secret::from_file(&file("b", "tok\r\n")).expect("read");
        assert_eq!(s.expose(), "tok");
        let s = Secret::from_file(&file("c", "  spaced  ")).expect("read");
        assert_eq!(s.expose(), "  spaced  ", "only line ends are stripped");
        for empty in ["", "\n", "\r\n\n"] {
            let e = Secret::from_file(&file("d", empty)).expect_err("empty");
            assert!(matches!(e, SecretFileError::Empty), "{e}");
        }
        let e = Secret::from_file(&dir.path().join("missing")).expect_err("missing");
        assert!(e.to_string().starts_with("cannot read it: "), "{e}");
    }
}
