//! UTC times: the wall clock ([`now_us`]) every layer stamps with, and one formatter for
//! every timestamp the project writes (MQTT read messages, pcapng comments), correct for
//! every `u64` of microseconds a reader may send.

use std::time::{SystemTime, UNIX_EPOCH};

/// The wall clock now, UTC µs since the Unix epoch (0 if the clock is before it).
pub fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

/// `us` (UTC µs since the Unix epoch) as RFC 3339 with microseconds, e.g.
/// `2023-11-14T22:13:20.000010Z`. RFC 3339 has four-digit years only: a time past
/// 9999-12-31 (a reader's clock gone wrong, or a hostile peer's) is written with ISO 8601's
/// expanded year, `+10000-01-01T00:00:00.000000Z`, rather than refused.
pub fn rfc3339_micros(us: u64) -> String {
    let secs = us / 1_000_000;
    let (days, s) = (secs / 86_400, secs % 86_400);
    // Every u64 of µs is under 2.2·10⁸ days: the day count fits an i64 with room to spare.
    let (y, m, d) = civil_from_days(days as i64);
    let sign = if y > 9999 { "+" } else { "" };
    format!(
        "{sign}{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{:06}Z",
        s / 3600,
        s / 60 % 60,
        s % 60,
        us % 1_000_000
    )
}

/// Year, month, day of a day count since 1970-01-01 (proleptic Gregorian calendar), by the
/// era arithmetic of H. Hinnant's "chrono-Compatible Low-Level Date Algorithms".
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Days since 1970-01-01 of a civil date (the inverse, counted the slow way).
    fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
        let leap = |y: i64| (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
        let year_days = |y: i64| if leap(y) { 366 } else { 365 };
        // Whole 400-year eras (146,097 days each) first, then years one by one.
        let eras = (y - 1970).div_euclid(400);
        let mut days = eras * 146_097;
        for year in 1970 + eras * 400..y {
            days += year_days(year);
        }
        let months = [
            31,
            if leap(y) { 29 } else { 28 },
            31,
            30,
            31,
            30,
            31,
            31,
            30,
            31,
            30,
            31,
        ];
        days + months[..(m - 1) as usize].iter().sum::<i64>() + i64::from(d) - 1
    }

    /// Parses what [`rfc3339_micros`] writes back to µs.
    fn parse(text: &str) -> u64 {
        let body = text.strip_prefix('+').unwrap_or(text);
        let (date, time) = body.split_once('T').expect("a T");
        let mut date = date.split('-').map(|v| v.parse::<i64>().expect("a number"));
        let (y, m, d) = (
            date.next().expect("year"),
            date.next().expect("month") as u32,
            date.next().expect("day") as u32,
        );
        assert!((1..=12).contains(&m) && (1..=31).contains(&d), "{text}");
        let time = time.strip_suffix('Z').expect("a Z");
        let (hms, micros) = time.split_once('.').expect("a fraction");
        let hms: Vec<u64> = hms
            .split(':')
            .map(|v| v.parse().expect("a number"))
            .collect();
        assert!(hms[0] < 24 && hms[1] < 60 && hms[2] < 60, "{text}");
        let days = days_from_civil(y, m, d) as u64;
        ((days * 86_400 + hms[0] * 3600 + hms[1] * 60 + hms[2]) * 1_000_000)
            + micros.parse::<u64>().expect("µs")
    }

    #[test]
    fn known_instants_are_written_as_humantime_and_rfc_3339_write_them() {
        for (us, text) in [
            (0, "1970-01-01T00:00:00.000000Z"),
            (1_700_000_000_000_010, "2023-11-14T22:13:20.000010Z"),
            // A leap day, and the last µs of a century year that is not a leap year.
            (951_782_400_000_000, "2000-02-29T00:00:00.000000Z"),
            (4_107_542_399_999_999, "2100-02-28T23:59:59.999999Z"),
            (253_402_300_799_999_999, "9999-12-31T23:59:59.999999Z"),
            // Past RFC 3339's years: expanded, where humantime failed (and `to_string`
            // panicked).
            (253_402_300_800_000_000, "+10000-01-01T00:00:00.000000Z"),
        ] {
            assert_eq!(rfc3339_micros(us), text, "{us}");
            let t = std::time::UNIX_EPOCH + std::time::Duration::from_micros(us);
            if us < 253_402_300_800_000_000 {
                assert_eq!(humantime::format_rfc3339_micros(t).to_string(), text);
            }
        }
        assert_eq!(rfc3339_micros(u64::MAX), "+586524-01-19T08:01:49.551615Z");
    }

    proptest! {
        #[test]
        fn every_u64_is_written_and_reads_back(us in any::<u64>()) {
            prop_assert_eq!(parse(&rfc3339_micros(us)), us);
        }
    }
}
