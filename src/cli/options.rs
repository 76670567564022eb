//! The valid range of every number the command line takes, in one place: each numeric option
//! of every command parses through [`parser`] with its entry of [`RANGES`], so a value out of
//! range is refused before any work starts, with the option, the range and why
//! (`docs/options.md`). A unit test of the binary walks every command's options and checks
//! that each number has an entry here and that its bounds hold.

/// The valid values of one numeric option (by its long name; the same name has the same
/// meaning on every command).
#[derive(Clone, Copy, Debug)]
pub struct Range {
    /// The option's long name, without the dashes.
    pub name: &'static str,
    /// Smallest valid value.
    pub min: f64,
    /// Largest valid value.
    pub max: f64,
    /// Whether only whole numbers are valid.
    pub integer: bool,
    /// Why the range is what it is, for the error message.
    pub why: &'static str,
}

const fn int(name: &'static str, min: f64, max: f64, why: &'static str) -> Range {
    Range {
        name,
        min,
        max,
        integer: true,
        why,
    }
}

const fn real(name: &'static str, min: f64, max: f64, why: &'static str) -> Range {
    Range {
        name,
        min,
        max,
        integer: false,
        why,
    }
}

/// An hour in milliseconds.
const HOUR_MS: f64 = 3_600_000.0;

/// Every numeric option of every command.
pub const RANGES: &[Range] = &[
    int(
        "record-max-bytes",
        512.0,
        u64::MAX as f64,
        "a part must hold its header line and a frame or more",
    ),
    int(
        "connect-timeout-ms",
        1.0,
        HOUR_MS,
        "milliseconds, at most an hour",
    ),
    int(
        "pose-interval-ms",
        1.0,
        10_000.0,
        "milliseconds between pose samples, at most 10 s",
    ),
    int(
        "conn",
        1.0,
        u32::MAX as f64,
        "connections are numbered from 1",
    ),
    real("seconds", 1e-3, 1e9, "a positive number of seconds"),
    int(
        "antennas",
        1.0,
        u16::MAX as f64,
        "antenna ports are numbered from 1",
    ),
    int(
        "report-every",
        1.0,
        u16::MAX as f64,
        "a report after N ≥ 1 tag reads",
    ),
    int("session", 0.0, 3.0, "Gen2 sessions are S0 to S3"),
    int(
        "search-mode",
        0.0,
        u16::MAX as f64,
        "an ImpinjInventorySearchMode value",
    ),
    int(
        "mode",
        0.0,
        u16::MAX as f64,
        "a ModeIdentifier of the reader's RF mode table",
    ),
    int(
        "keepalive-ms",
        0.0,
        HOUR_MS,
        "0 (no keepalives) or milliseconds, at most an hour",
    ),
    int("backoff-ms", 1.0, HOUR_MS, "milliseconds, at most an hour"),
    int(
        "backoff-max-ms",
        1.0,
        HOUR_MS,
        "milliseconds, at most an hour",
    ),
    int("shard-count", 1.0, u16::MAX as f64, "at least one shard"),
    int(
        "max-clients",
        1.0,
        65_536.0,
        "at least one client, at most 65536",
    ),
    int("publish-queue", 1.0, 100_000_000.0, "at least one message"),
    int(
        "publish-window-ms",
        0.0,
        60_000.0,
        "0 (send at once) or milliseconds, at most a minute",
    ),
    real(
        "presence-silence-s",
        1e-3,
        1e9,
        "a positive number of seconds",
    ),
    real("presence-move-m", 0.0, 1e6, "metres, 0 or more"),
    real("live-speed", 0.0, 1e6, "0 (no live run) or a speed factor"),
    int(
        "runs",
        0.0,
        1e6,
        "0 (no Monte-Carlo variants) or a number of runs",
    ),
    int("repeat", 1.0, 1e6, "at least one repetition"),
    real("min-rssi", -200.0, 50.0, "dBm"),
    int(
        "mss",
        536.0,
        65_495.0,
        "a TCP payload size: IPv4's minimum MSS (RFC 879) to the most an IPv4 packet holds",
    ),
];

/// The range of option `name`; panics (a programming error caught by the options test) if it
/// has none.
pub fn range(name: &str) -> &'static Range {
    RANGES
        .iter()
        .find(|r| r.name == name)
        .unwrap_or_else(|| panic!("option --{name} has no entry in cli::options::RANGES"))
}

/// Parses `text` as a value of option `name`, within its range.
pub fn check(name: &str, text: &str) -> Result<f64, String> {
    let r = range(name);
    let v: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number ({})", r.why))?;
    let whole = v.fract() == 0.0;
    if !v.is_finite() || v < r.min || v > r.max || (r.integer && !whole) {
        let kind = if r.integer {
            "a whole number"
        } else {
            "a number"
        };
        let max = if r.max >= u32::MAX as f64 {
            "".to_string()
        } else {
            format!(" to {}", show(r.max))
        };
        return Err(format!(
            "`{text}` is out of range: --{name} takes {kind} from {}{max} ({})",
            show(r.min),
            r.why
        ));
    }
    Ok(v)
}

fn show(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v}")
    }
}

/// A clap value parser for option `name` giving a `T` (u8, u16, u32, u64, usize or f64).
pub fn parser<T: FromRange>(name: &'static str) -> impl Fn(&str) -> Result<T, String> + Clone {
    move |text: &str| {
        let v = check(name, text)?;
        // Whole numbers within the range parse exactly as the integer type (the range fits
        // the type: checked by the options test).
        if range(name).integer {
            T::from_text(text.trim()).ok_or_else(|| format!("`{text}` does not fit --{name}"))
        } else {
            Ok(T::from_f64(v))
        }
    }
}

/// A number type an option gives.
pub trait FromRange: Send + Sync + Clone + 'static {
    /// From the option's text (whole numbers).
    fn from_text(text: &str) -> Option<Self>;
    /// From a checked real value.
    fn from_f64(v: f64) -> Self;
}

macro_rules! from_range_int {
    ($($t:ty),*) => {$(
        impl FromRange for $t {
            fn from_text(text: &str) -> Option<Self> {
                text.parse().ok()
            }
            fn from_f64(v: f64) -> Self {
                v as $t
            }
        }
    )*};
}
from_range_int!(u8, u16, u32, u64, usize);

impl FromRange for f64 {
    fn from_text(text: &str) -> Option<Self> {
        text.parse().ok()
    }
    fn from_f64(v: f64) -> Self {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_range_values_are_refused_with_the_range_and_why() {
        let p = parser::<u64>("record-max-bytes");
        assert_eq!(p("4096"), Ok(4096));
        for bad in ["0", "1", "511", "-5", "1.5", "many", "NaN"] {
            let e = p(bad).expect_err(bad);
            assert!(e.contains(bad) && e.contains("header line"), "{e}");
        }
        assert!(p("0")
            .expect_err("0")
            .contains("--record-max-bytes takes a whole number from 512"));
        let s = parser::<f64>("seconds");
        assert_eq!(s("2.5"), Ok(2.5));
        for bad in ["0", "-1", "inf", "1e10"] {
            assert!(s(bad).is_err(), "{bad}");
        }
        assert_eq!(parser::<u8>("session")("3"), Ok(3));
        assert!(parser::<u8>("session")("4").is_err());
    }

    #[test]
    fn every_range_is_well_formed_and_named_once() {
        for (i, r) in RANGES.iter().enumerate() {
            assert!(r.min <= r.max, "{}", r.name);
            assert!(!r.why.is_empty(), "{}", r.name);
            assert!(
                RANGES[i + 1..].iter().all(|o| o.name != r.name),
                "{} twice",
                r.name
            );
        }
    }
}
