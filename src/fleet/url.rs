//! Broker addresses: `mqtt://[USER:PASS@]HOST[:PORT][/PREFIX]` and `mqtts://…` (TLS).

use std::fmt;

use crate::secret::Secret;

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
    /// Password, if any (only with a user); shown as `***`.
    pub password: Option<Secret>,
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
    /// A password apart from the URL, which has one already.
    #[error("'{0}': a password is given both in the URL and apart from it")]
    TwoPasswords(String),
    /// A password apart from the URL, which names no user to go with it.
    #[error(
        "'{0}': a password is given apart from the URL, which names no user (mqtt://USER@HOST)"
    )]
    PasswordWithoutUser(String),
}

/// A broker address as given (`--publish`, `--subscribe`): its text, which may hold a
/// password, shown with the password hidden (`Debug` too), so an options struct holding it
/// prints none.
#[derive(Clone, PartialEq, Eq)]
pub struct BrokerAddress(String);

impl BrokerAddress {
    /// The address as given, password included: for [`BrokerUrl::parse`] only.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl From<String> for BrokerAddress {
    fn from(text: String) -> BrokerAddress {
        BrokerAddress(text)
    }
}

impl From<&str> for BrokerAddress {
    fn from(text: &str) -> BrokerAddress {
        BrokerAddress(text.to_owned())
    }
}

impl fmt::Display for BrokerAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&redact(&self.0))
    }
}

impl fmt::Debug for BrokerAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "BrokerAddress({})", redact(&self.0))
    }
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
            Some(c) => login(c, url)?,
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
        // An `@` past the authority: most likely a password holding an unescaped `/`, whose
        // pieces would be taken for the port and the prefix: those are not echoed then.
        let echo = |part: &str| {
            if credentials.is_none() && prefix.contains('@') {
                "***".to_owned()
            } else {
                part.to_owned()
            }
        };
        let port = match port {
            None if tls => MQTTS_PORT,
            None => MQTT_PORT,
            Some(p) => match p.parse::<u16>() {
                Ok(n) if n > 0 => n,
                _ => {
                    return Err(UrlError::Port {
                        url: redact(url),
                        port: echo(p),
                    })
                }
            },
        };
        let prefix = prefix.trim_end_matches('/');
        let bad = |reason| UrlError::Prefix {
            url: redact(url),
            prefix: echo(prefix),
            reason,
        };
        if prefix.contains(['+', '#']) {
            return Err(bad("MQTT wildcards (+, #) are not allowed"));
        }
        if prefix.contains('@') {
            return Err(bad("'@' is not allowed (in a password, write '/' as %2F and '@' as %40, or give it apart: --mqtt-password-file)"));
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

    /// This address with `password`, given apart from the URL (`--mqtt-password`, its file or
    /// its environment variable), when there is one: the URL must name the user and no
    /// password of its own.
    pub fn with_password(mut self, password: Option<Secret>) -> Result<BrokerUrl, UrlError> {
        let Some(password) = password else {
            return Ok(self);
        };
        if self.password.is_some() {
            return Err(UrlError::TwoPasswords(self.to_string()));
        }
        if self.user.is_none() {
            return Err(UrlError::PasswordWithoutUser(self.to_string()));
        }
        self.password = Some(password);
        Ok(self)
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

/// The user and password of `credentials` (`USER[:PASS]`, percent-escaped) in `url`.
fn login(credentials: &str, url: &str) -> Result<(Option<String>, Option<Secret>), UrlError> {
    let (u, p) = match credentials.split_once(':') {
        Some((u, p)) => (u, Some(p)),
        None => (credentials, None),
    };
    let unescape = |s: &str| percent_decode(s).ok_or(UrlError::Escape(redact(url)));
    let password = p.map(unescape).transpose()?.map(Secret::new);
    Ok((Some(unescape(u)?), password))
}

/// `url` with any password replaced by `***`, for messages: everything between the first
/// `:` after the scheme and the last `@` (so a password holding an unescaped `/` or `@`,
/// which does not parse, is hidden all the same; at worst more is hidden than the password).
fn redact(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_owned();
    };
    match rest.rsplit_once('@') {
        Some((cred, host)) => match cred.split_once(':') {
            Some((user, _)) => format!("{scheme}://{user}:***@{host}"),
            None => url.to_owned(),
        },
        None => url.to_owned(),
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
        assert_eq!(u.password.as_ref().map(Secret::expose), Some("p@ss"));
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
        // A password with an unescaped `/` or `@` does not parse, and is not shown either.
        let urls = [
            "mqtt://gw:se/cret@h",
            "mqtt://gw:se@cret@h:0",
            "mqtt://gw:1/+cret@h",
            "mqtt://gw:1/cret@h",
        ];
        for url in urls {
            let e = BrokerUrl::parse(url).expect_err("does not parse");
            assert!(!e.to_string().contains("cret"), "{e}");
            assert!(!e.to_string().contains("se"), "{e}");
        }
    }

    #[test]
    fn a_password_apart_needs_the_user_and_no_password_in_the_url() {
        let pass = || Some(Secret::new("apart"));
        let u = BrokerUrl::parse("mqtt://gw@h").expect("parses");
        let u = u.with_password(pass()).expect("a user without a password");
        assert_eq!(u.password.as_ref().map(Secret::expose), Some("apart"));
        assert_eq!(u.to_string(), "mqtt://gw:***@h:1883");
        let e = (BrokerUrl::parse("mqtt://gw:inurl@h").expect("parses"))
            .with_password(pass())
            .expect_err("two passwords");
        assert!(matches!(e, UrlError::TwoPasswords(_)));
        assert!(!e.to_string().contains("inurl"), "{e}");
        let e = (BrokerUrl::parse("mqtt://h").expect("parses"))
            .with_password(pass())
            .expect_err("no user");
        assert!(matches!(e, UrlError::PasswordWithoutUser(_)));
        let same = BrokerUrl::parse("mqtt://gw:inurl@h").expect("parses");
        assert_eq!(same.clone().with_password(None), Ok(same));
    }

    #[test]
    fn a_broker_address_as_given_shows_no_password() {
        let a = BrokerAddress::from("mqtts://gw:s3cret@h:8883/p");
        assert_eq!(a.to_string(), "mqtts://gw:***@h:8883/p");
        assert!(!format!("{a:?}").contains("s3cret"));
        assert_eq!(a.as_str(), "mqtts://gw:s3cret@h:8883/p");
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
