//! The two text formats `GET /metrics` serves, chosen by the request's `Accept`:
//! OpenMetrics 1.0 (what prometheus-client writes, and what Prometheus asks for first) and
//! the classic Prometheus text format 0.0.4, converted from it, for the clients that ask for
//! `text/plain` or name neither format (curl, browsers, `promtool check metrics`).
//!
//! The two differ where a classic parser would misread OpenMetrics: a counter's family is
//! `foo` with the sample `foo_total` in OpenMetrics but `foo_total` in the classic format (a
//! classic parser finds no type for `foo_total` in OpenMetrics text); `# UNIT` and `# EOF`
//! lines, exemplars and `_created` samples are OpenMetrics only.

use std::collections::BTreeSet;

/// A text format of the metrics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// OpenMetrics 1.0.0 text.
    OpenMetrics,
    /// The Prometheus text format 0.0.4.
    Classic,
}

impl Format {
    /// The `Content-Type` of a response in this format.
    pub fn content_type(self) -> &'static str {
        match self {
            Format::OpenMetrics => "application/openmetrics-text; version=1.0.0; charset=utf-8",
            Format::Classic => "text/plain; version=0.0.4; charset=utf-8",
        }
    }
}

/// One media range of an `Accept` header: lower-case type, its `version` parameter and `q`.
struct Range<'a> {
    media: String,
    version: Option<&'a str>,
    q: f32,
}

fn range(item: &str) -> Option<Range<'_>> {
    let mut parts = item.split(';');
    let media = parts.next()?.trim().to_ascii_lowercase();
    if media.is_empty() {
        return None;
    }
    let (mut version, mut q) = (None, 1.0);
    for param in parts {
        let Some((key, value)) = param.split_once('=') else {
            continue;
        };
        let value = value.trim().trim_matches('"');
        match key.trim().to_ascii_lowercase().as_str() {
            "version" => version = Some(value),
            "q" => q = value.parse().unwrap_or(0.0),
            _ => {}
        }
    }
    Some(Range { media, version, q })
}

/// The format for a request with `accept` (its `Accept` header, if any): the first of its
/// media ranges, by falling `q` and then in the order given, that names OpenMetrics (no
/// version, 1.0.0 or 0.0.1) or `text/plain` (no version or 0.0.4); the classic format when
/// none does. A range with `q=0` is refused, and wildcards name neither format: as the
/// Prometheus Go client negotiates, OpenMetrics only for a client that asks for it.
pub fn negotiate(accept: Option<&str>) -> Format {
    let mut ranges: Vec<Range> = accept
        .unwrap_or("")
        .split(',')
        .filter_map(range)
        .filter(|r| r.q > 0.0)
        .collect();
    // Stable: equal q keeps the client's order.
    ranges.sort_by(|a, b| b.q.total_cmp(&a.q));
    for r in ranges {
        match (r.media.as_str(), r.version) {
            ("application/openmetrics-text", None | Some("1.0.0" | "0.0.1")) => {
                return Format::OpenMetrics
            }
            ("text/plain", None | Some("0.0.4")) => return Format::Classic,
            _ => {}
        }
    }
    Format::Classic
}

/// The metric name a sample line starts with.
fn sample_name(line: &str) -> &str {
    let end = line.find(['{', ' ']).unwrap_or(line.len());
    &line[..end]
}

/// Where a sample line's name and label set end (label values may hold any character,
/// quotes and backslashes escaped).
fn labels_end(line: &str) -> usize {
    let start = sample_name(line).len();
    if !line[start..].starts_with('{') {
        return start;
    }
    let (mut quoted, mut escaped) = (false, false);
    for (i, c) in line[start..].char_indices() {
        match c {
            _ if escaped => escaped = false,
            '\\' if quoted => escaped = true,
            '"' => quoted = !quoted,
            '}' if !quoted => return start + i + 1,
            _ => {}
        }
    }
    line.len()
}

/// A sample line without its exemplar (which follows the value after " # ").
fn without_exemplar(line: &str) -> &str {
    let end = labels_end(line);
    match line[end..].find(" # ") {
        Some(at) => &line[..end + at],
        None => line,
    }
}

/// `# HELP`/`# TYPE` line `rest` (after the keyword) for the classic format: a counter's
/// family takes its samples' `_total`, an info family its `_info`; a type the classic format
/// lacks becomes the nearest it has (info and stateset: gauge; unknown and gaugehistogram,
/// whose `_gcount` and `_gsum` no classic type has: untyped).
fn descriptor(
    keyword: &str,
    rest: &str,
    counters: &BTreeSet<&str>,
    infos: &BTreeSet<&str>,
) -> String {
    let (name, tail) = rest.split_once(' ').unwrap_or((rest, ""));
    let suffix = if counters.contains(name) {
        "_total"
    } else if infos.contains(name) {
        "_info"
    } else {
        ""
    };
    let tail = match (keyword, tail) {
        ("TYPE", "unknown" | "gaugehistogram") => "untyped",
        ("TYPE", "info" | "stateset") => "gauge",
        _ => tail,
    };
    format!("# {keyword} {name}{suffix} {tail}")
}

/// The classic text format of `openmetrics`, an OpenMetrics text as prometheus-client
/// writes it: counters' and info metrics' families renamed after their samples, `# UNIT`,
/// `# EOF`, exemplars and counters' `_created` samples left out.
pub fn classic(openmetrics: &str) -> String {
    let families = |kind: &str| -> BTreeSet<&str> {
        openmetrics
            .lines()
            .filter_map(|l| l.strip_prefix("# TYPE "))
            .filter_map(|r| r.split_once(' '))
            .filter(|(_, t)| *t == kind)
            .map(|(name, _)| name)
            .collect()
    };
    let (counters, infos) = (families("counter"), families("info"));
    let mut out = String::with_capacity(openmetrics.len());
    for line in openmetrics.lines() {
        let text = if line == "# EOF" || line.starts_with("# UNIT ") {
            continue;
        } else if let Some(rest) = line.strip_prefix("# HELP ") {
            descriptor("HELP", rest, &counters, &infos)
        } else if let Some(rest) = line.strip_prefix("# TYPE ") {
            descriptor("TYPE", rest, &counters, &infos)
        } else {
            let name = sample_name(line);
            let created = name
                .strip_suffix("_created")
                .is_some_and(|family| counters.contains(family));
            if created {
                continue;
            }
            without_exemplar(line).to_owned()
        };
        out.push_str(&text);
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prometheus_gets_openmetrics_and_a_client_naming_no_format_gets_the_classic_text() {
        // What Prometheus 2.42 (Debian 12's) sends, and Prometheus 3's default.
        let p2 = "application/openmetrics-text;version=1.0.0,application/openmetrics-text;\
                  version=0.0.1;q=0.75,text/plain;version=0.0.4;q=0.5,*/*;q=0.1";
        let p3 = "application/openmetrics-text;version=1.0.0;escaping=allow-utf-8;q=0.6,\
                  application/openmetrics-text;version=0.0.1;q=0.5,text/plain;version=1.0.0;\
                  escaping=allow-utf-8;q=0.4,text/plain;version=0.0.4;q=0.3,*/*;q=0.2";
        assert_eq!(negotiate(Some(p2)), Format::OpenMetrics);
        assert_eq!(negotiate(Some(p3)), Format::OpenMetrics);
        for accept in [
            None,
            Some(""),
            Some("*/*"),
            Some("text/html,application/xhtml+xml,application/xml;q=0.9,*/*;q=0.8"),
            Some("text/plain;version=0.0.4"),
            Some("TEXT/PLAIN"),
            // Prometheus configured for the classic format only.
            Some("text/plain;version=0.0.4;q=0.3,*/*;q=0.2"),
            // OpenMetrics refused, or a version this server cannot write.
            Some("application/openmetrics-text;q=0"),
            Some("application/openmetrics-text;version=2.0.0"),
        ] {
            assert_eq!(negotiate(accept), Format::Classic, "{accept:?}");
        }
        // The higher q wins, whatever the order; equal q, the first.
        assert_eq!(
            negotiate(Some("text/plain;q=0.5, application/openmetrics-text")),
            Format::OpenMetrics
        );
        assert_eq!(
            negotiate(Some("text/plain, application/openmetrics-text")),
            Format::Classic
        );
        assert_eq!(
            negotiate(Some("application/openmetrics-text; version=\"1.0.0\"")),
            Format::OpenMetrics
        );
    }

    #[test]
    fn the_classic_text_names_counter_families_after_their_samples() {
        let om = "# HELP x_frames Frames.\n# TYPE x_frames counter\nx_frames_total 3\n\
                  x_frames_created 1.7e9\n\
                  # HELP x_wait_seconds Wait.\n# TYPE x_wait_seconds histogram\n\
                  # UNIT x_wait_seconds seconds\nx_wait_seconds_sum 0.5\nx_wait_seconds_count 2\n\
                  x_wait_seconds_bucket{le=\"0.1\"} 1 # {trace=\"a\"} 0.05\n\
                  x_wait_seconds_bucket{le=\"+Inf\"} 2\n\
                  # HELP x_build Build.\n# TYPE x_build info\nx_build_info{v=\"1 # 2\"} 1\n\
                  # TYPE x_odd unknown\nx_odd 1\n# EOF\n";
        let want =
            "# HELP x_frames_total Frames.\n# TYPE x_frames_total counter\nx_frames_total 3\n\
                    # HELP x_wait_seconds Wait.\n# TYPE x_wait_seconds histogram\n\
                    x_wait_seconds_sum 0.5\nx_wait_seconds_count 2\n\
                    x_wait_seconds_bucket{le=\"0.1\"} 1\nx_wait_seconds_bucket{le=\"+Inf\"} 2\n\
                    # HELP x_build_info Build.\n# TYPE x_build_info gauge\n\
                    x_build_info{v=\"1 # 2\"} 1\n# TYPE x_odd untyped\nx_odd 1\n";
        assert_eq!(classic(om), want);
        assert_eq!(
            without_exemplar(r#"a{v="\"}"} 1 # {t="x"} 2"#),
            r#"a{v="\"}"} 1"#
        );
    }
}
