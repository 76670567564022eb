//! Broker addresses: `mqtt://[USER:PASS@]HOST[:PORT][/PREFIX]` and `mqtts://…` (TLS).

use std::fmt;

/// MQTT's registered port (plain TCP).
pub const MQTT_PORT: u16 = 1883;

/// MQTT over TLS's registered port.
pub const MQTTS_PORT: u16 = 8883;

/// Where a broker is and how to log in.
#[derive(Clone, PartialEq, Eq)]
pub struct BrokerUrl {
    /// `mqtts://`: TLS to the broker.
    pub tls: bool,
    /// Host name or address (an IPv6 address without its brackets).
    pub host: String,
    /// TCP port.
    pub port: u16,
    /// User name, if any.
    pub user: Option<String>,
    /// Password, if any (only with a user).
    pub password: Option<String>,
    /// Topic prefix (no leading or trailing `/`), empty for none.
    pub prefix: String,
}

/// Why a broker address is refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum UrlError {
    /// Not `mqtt://` or `mqtts://`.
    #[error("'{0}': the scheme must be mqtt:// or mqtts://")]
    Scheme(String),
    /// No host.
    #[error("'{0}': no host")]
    Host(String),
    /// A port that is not 1–65535.
    #[error("'{url}': port '{port}' is not a number 1-65535")]
    Port {
        /// The address.
        url: String,
        /// The port as given.
        port: String,
    },
    /// A prefix with MQTT wildcards or empty levels.
    #[error("'{url}': prefix '{prefix}': {reason}")]
    Prefix {
        /// The address.
        url: String,
        /// The prefix as given.
        prefix: String,
        /// Why.
        reason: &'static str,
    },
    /// A `%` escape that is not two hex digits of UTF-8.
    #[error("'{0}': bad percent escape in the user or password")]
    Escape(String),
}

impl BrokerUrl {
    /// Parses `url`.
    pub fn parse(url: &str) -> Result<BrokerUrl, UrlError> {
        let (tls, rest) = if let Some(r) = url.strip_prefix("mqtt://") {
            (false, r)
        } else if let Some(r) = url.strip_prefix("mqtts://") {
            (true, r)
        } else {
            return Err(UrlError::Scheme(redact(url)));
        };
        let (authority, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        let (credentials, hostport) = match authority.rsplit_once('@') {
            Some((c, h)) => (Some(c), h),
            None => (None, authority),
        };
        let (user, password) = match credentials {
            Some(c) => {
                let (u, p) = match c.split_once(':') {
                    Some((u, p)) => (u, Some(p)),
                    None => (c, None),
                };
                let unescape = |s: &str| percent_decode(s).ok_or(UrlError::Escape(redact(url)));
                (Some(unescape(u)?), p.map(unescape).transpose()?)
            }
            None => (None, None),
        };
        let (host, port) = if let Some(v6) = hostport.strip_prefix('[') {
            match v6.split_once(']') {
                Some((h, p)) => (h, p.strip_prefix(':')),
                None => return Err(UrlError::Host(redact(url))),
            }
        } else {
            match hostport.rsplit_once(':') {
                Some((h, p)) => (h, Some(p)),
                None => (hostport, None),
            }
        };
        if host.is_empty() {
            return Err(UrlError::Host(redact(url)));
        }
        let port = match port {
            None => {
                if tls {
                    MQTTS_PORT
                } else {
                    MQTT_PORT
                }
            }
            Some(p) => match p.parse::<u16>() {
                Ok(n) if n > 0 => n,
                _ => {
                    return Err(UrlError::Port {
                        url: redact(url),
                        port: p.to_owned(),
                    })
                }
            },
        };
        let prefix = prefix.trim_end_matches('/');
        let bad = |reason| UrlError::Prefix {
            url: redact(url),
            prefix: prefix.to_owned(),
            reason,
        };
        if prefix.contains(['+', '#']) {
            return Err(bad("MQTT wildcards (+, #) are not allowed"));
        }
        if !prefix.is_empty() && prefix.split('/').any(str::is_empty) {
            return Err(bad("empty topic level"));
        }
        Ok(BrokerUrl {
            tls,
            host: host.to_owned(),
            port,
            user,
            password,
            prefix: prefix.to_owned(),
        })
    }

    /// The topic `rest` under the prefix: `PREFIX/rest`, or `rest` without one.
    pub fn topic(&self, rest: &str) -> String {
        if self.prefix.is_empty() {
            rest.to_owned()
        } else {
            format!("{}/{rest}", self.prefix)
        }
    }
}

/// Shown with the password hidden.
impl fmt::Display for BrokerUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let scheme = if self.tls { "mqtts" } else { "mqtt" };
        write!(f, "{scheme}://")?;
        if let Some(u) = &self.user {
            write!(f, "{u}")?;
            if self.password.is_some() {
                write!(f, ":***")?;
            }
            write!(f, "@")?;
        }
        if self.host.contains(':') {
            write!(f, "[{}]:{}", self.host, self.port)?;
        } else {
            write!(f, "{}:{}", self.host, self.port)?;
        }
        if !self.prefix.is_empty() {
            write!(f, "/{}", self.prefix)?;
        }
        Ok(())
    }
}

impl fmt::Debug for BrokerUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "BrokerUrl({self})")
    }
}

/// `url` with any password replaced by `***`, for error messages.
fn redact(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_owned();
    };
    let authority = rest.split('/').next().unwrap_or("");
    match authority.rsplit_once('@') {
        Some((cred, _)) if cred.contains(':') => {
            let user = cred.split(':').next().unwrap_or("");
            format!("{scheme}://{user}:***@{}", &rest[cred.len() + 1..])
        }
        _ => url.to_owned(),
    }
}

/// `s` with `%XX` escapes decoded; `None` when one is malformed or the result is not UTF-8.
fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = s.get(i + 1..i + 3)?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_part_and_defaults_the_port_by_scheme() {
        let u = BrokerUrl::parse("mqtt://127.0.0.1").expect("parses");
        assert_eq!((u.tls, u.host.as_str(), u.port), (false, "127.0.0.1", 1883));
        assert_eq!((u.user, u.password, u.prefix.as_str()), (None, None, ""));
        let u = BrokerUrl::parse("mqtts://gw:p%40ss@broker.local:18883/site/a/").expect("parses");
        assert!(u.tls);
        assert_eq!((u.host.as_str(), u.port), ("broker.local", 18883));
        assert_eq!(u.user.as_deref(), Some("gw"));
        assert_eq!(u.password.as_deref(), Some("p@ss"));
        assert_eq!(u.prefix, "site/a");
        assert_eq!(u.topic("v1/refs"), "site/a/v1/refs");
        assert_eq!(BrokerUrl::parse("mqtts://h").expect("parses").port, 8883);
        let v6 = BrokerUrl::parse("mqtt://[::1]:1884").expect("parses");
        assert_eq!((v6.host.as_str(), v6.port), ("::1", 1884));
        assert_eq!(v6.to_string(), "mqtt://[::1]:1884");
    }

    #[test]
    fn shows_and_reports_without_the_password() {
        let u = BrokerUrl::parse("mqtt://gw:secret@h/p").expect("parses");
        assert_eq!(u.to_string(), "mqtt://gw:***@h:1883/p");
        let e = BrokerUrl::parse("mqtt://gw:secret@h:99999").expect_err("bad port");
        assert!(!e.to_string().contains("secret"), "{e}");
        assert!(e.to_string().contains("99999"), "{e}");
    }

    #[test]
    fn refuses_bad_addresses_naming_the_part() {
        assert!(matches!(
            BrokerUrl::parse("http://h"),
            Err(UrlError::Scheme(_))
        ));
        assert!(matches!(
            BrokerUrl::parse("mqtt://"),
            Err(UrlError::Host(_))
        ));
        assert!(matches!(
            BrokerUrl::parse("mqtt://h:0"),
            Err(UrlError::Port { .. })
        ));
        assert!(matches!(
            BrokerUrl::parse("mqtt://h/a/#"),
            Err(UrlError::Prefix { .. })
        ));
        assert!(matches!(
            BrokerUrl::parse("mqtt://h/a//b"),
            Err(UrlError::Prefix { .. })
        ));
        assert!(matches!(
            BrokerUrl::parse("mqtt://u:%zz@h"),
            Err(UrlError::Escape(_))
        ));
    }
}
