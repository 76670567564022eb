//! LLRP over TLS: certificates and keys from PEM files, the server side ([`acceptor`]) and
//! the client side ([`Connector`]), on rustls with its `ring` provider.
//!
//! LLRP over TLS is the same byte stream inside a TLS session; readers that offer it listen on
//! port 5085 by convention ([`LLRP_TLS_PORT`]), beside plain LLRP on 5084. Nothing here picks
//! the port: the listen and connect addresses say it.
//!
//! The client trusts either the certificates of a CA file (`--tls-ca`) or, as an explicit
//! opt-in with a logged warning, any certificate (`--tls-insecure`): readers ship self-signed
//! certificates, so the system's roots would not help, and none are loaded. A certificate of
//! the CA file that the reader presents itself is trusted as it is (pinned), even where WebPKI
//! would refuse it as an end entity: `openssl req -x509` and many readers mark their
//! self-signed certificate as a CA. With
//! `--tls-insecure` the handshake's signatures are still checked against the certificate the
//! reader sent; only who signed that certificate, its validity period and its name are not.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use tokio::net::TcpStream;
use tokio_rustls::rustls;
use tokio_rustls::rustls::client::danger::{
    HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier,
};
use tokio_rustls::rustls::client::WebPkiServerVerifier;
use tokio_rustls::rustls::crypto::CryptoProvider;
use tokio_rustls::rustls::pki_types::pem::{self, PemObject};
use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName, UnixTime};
use tokio_rustls::rustls::{ClientConfig, DigitallySignedStruct, RootCertStore, ServerConfig};
use tokio_rustls::{TlsAcceptor, TlsConnector};

/// The port readers offer LLRP over TLS on, by convention (plain LLRP: 5084).
pub const LLRP_TLS_PORT: u16 = 5085;

/// Longest a TLS handshake may take, on either side.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// A TLS setting that cannot be used: a file that cannot be read or parsed, a certificate and
/// key that do not go together, a bad server name.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// The file cannot be read.
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: io::Error,
    },
    /// The file is not valid PEM.
    #[error("{}: not valid PEM: {reason}", path.display())]
    Pem {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        reason: String,
    },
    /// The file holds no certificate.
    #[error("{}: no certificate in it (a PEM file with `-----BEGIN CERTIFICATE-----` blocks is needed)", path.display())]
    NoCertificate {
        /// The file.
        path: PathBuf,
    },
    /// The file holds no private key.
    #[error("{}: no private key in it (a PEM `PRIVATE KEY`, `RSA PRIVATE KEY` or `EC PRIVATE KEY` block is needed)", path.display())]
    NoKey {
        /// The file.
        path: PathBuf,
    },
    /// A CA file's certificate cannot be used as a trust anchor.
    #[error("{}: not a usable CA certificate: {source}", path.display())]
    Ca {
        /// The file.
        path: PathBuf,
        /// Why.
        source: rustls::Error,
    },
    /// The certificate chain and the key cannot serve TLS together.
    #[error("certificate {} with key {}: {source}", cert.display(), key.display())]
    CertifiedKey {
        /// The certificate file.
        cert: PathBuf,
        /// The key file.
        key: PathBuf,
        /// Why.
        source: rustls::Error,
    },
    /// rustls refused the configuration.
    #[error("TLS configuration: {0}")]
    Config(#[from] rustls::Error),
    /// Not a DNS name or an IP address.
    #[error("{0:?} is not a TLS server name (a DNS name or an IP address)")]
    ServerName(String),
}

/// The crypto provider of every configuration here: rustls' `ring` provider, named
/// explicitly so that no process-wide default has to be installed.
fn provider() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

fn read(path: &Path) -> Result<Vec<u8>, TlsError> {
    std::fs::read(path).map_err(|source| TlsError::Read {
        path: path.to_owned(),
        source,
    })
}

fn pem_error(path: &Path, e: pem::Error) -> TlsError {
    TlsError::Pem {
        path: path.to_owned(),
        reason: e.to_string(),
    }
}

/// Every certificate of a PEM file, in order (a server's chain: its own first).
pub fn load_certs(path: &Path) -> Result<Vec<CertificateDer<'static>>, TlsError> {
    let bytes = read(path)?;
    let certs = CertificateDer::pem_slice_iter(&bytes)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| pem_error(path, e))?;
    if certs.is_empty() {
        return Err(TlsError::NoCertificate {
            path: path.to_owned(),
        });
    }
    Ok(certs)
}

/// The first private key of a PEM file (PKCS#8, PKCS#1 or SEC1).
pub fn load_key(path: &Path) -> Result<PrivateKeyDer<'static>, TlsError> {
    let bytes = read(path)?;
    PrivateKeyDer::from_pem_slice(&bytes).map_err(|e| match e {
        pem::Error::NoItemsFound => TlsError::NoKey {
            path: path.to_owned(),
        },
        e => pem_error(path, e),
    })
}

/// A server's certificate chain and private key, both PEM files (`--tls-cert`, `--tls-key`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ServerFiles {
    /// The certificate chain, the server's own certificate first.
    pub cert: PathBuf,
    /// Its private key.
    pub key: PathBuf,
}

impl ServerFiles {
    /// Loads both files and builds the server side ([`acceptor`]).
    pub fn acceptor(&self) -> Result<Acceptor, TlsError> {
        Ok(Acceptor(acceptor(&self.cert, &self.key)?))
    }
}

/// The server side of TLS, ready to take handshakes (cheap to clone).
#[derive(Clone)]
pub struct Acceptor(pub TlsAcceptor);

impl std::fmt::Debug for Acceptor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Acceptor")
    }
}

impl Acceptor {
    /// The server's handshake on an accepted `tcp` (within [`HANDSHAKE_TIMEOUT`]).
    pub async fn accept(
        &self,
        tcp: TcpStream,
    ) -> io::Result<tokio_rustls::server::TlsStream<TcpStream>> {
        with_timeout(self.0.accept(tcp)).await
    }
}

/// The server side: a certificate chain (`cert`, PEM) and its key (`key`, PEM); TLS 1.2 and
/// 1.3, no client certificates.
pub fn acceptor(cert: &Path, key: &Path) -> Result<TlsAcceptor, TlsError> {
    let chain = load_certs(cert)?;
    let private = load_key(key)?;
    let config = ServerConfig::builder_with_provider(provider())
        .with_safe_default_protocol_versions()?
        .with_no_client_auth()
        .with_single_cert(chain, private)
        .map_err(|source| TlsError::CertifiedKey {
            cert: cert.to_owned(),
            key: key.to_owned(),
            source,
        })?;
    Ok(TlsAcceptor::from(Arc::new(config)))
}

/// The TLS client configuration trusting `verify` (ring provider, TLS 1.2 and 1.3): for the
/// LLRP client and proxy and for MQTT brokers. With [`Verify::Insecure`] a warning is logged.
pub fn client_config(verify: &Verify) -> Result<Arc<ClientConfig>, TlsError> {
    let builder =
        ClientConfig::builder_with_provider(provider()).with_safe_default_protocol_versions()?;
    let config = match verify {
        Verify::Ca(path) => {
            let ca_error = |source| TlsError::Ca {
                path: path.clone(),
                source,
            };
            let certs = load_certs(path)?;
            let mut roots = RootCertStore::empty();
            for cert in &certs {
                roots.add(cert.clone()).map_err(ca_error)?;
            }
            let webpki = WebPkiServerVerifier::builder_with_provider(Arc::new(roots), provider())
                .build()
                .map_err(|e| ca_error(rustls::Error::General(e.to_string())))?;
            builder
                .dangerous()
                .with_custom_certificate_verifier(Arc::new(CaOrPinned {
                    webpki,
                    pinned: certs,
                }))
                .with_no_client_auth()
        }
        Verify::Insecure => {
            tracing::warn!(
                "TLS: the reader's certificate is not checked (--tls-insecure): any \
                 certificate is accepted, so the connection is encrypted but not \
                 authenticated"
            );
            builder
                .dangerous()
                .with_custom_certificate_verifier(Arc::new(AnyCertificate(provider())))
                .with_no_client_auth()
        }
    };
    Ok(Arc::new(config))
}

/// Which reader certificates a client accepts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Verify {
    /// Certificates issued by one of the CA certificates in this PEM file, for the server name
    /// connected to, or one of those very certificates (a reader's self-signed one, pinned).
    Ca(PathBuf),
    /// Any certificate (explicit opt-in: logged as a warning).
    Insecure,
}

/// The client side of TLS: whom to trust and, optionally, the name to expect.
#[derive(Clone)]
pub struct Connector {
    connector: TlsConnector,
    server_name: Option<ServerName<'static>>,
}

impl std::fmt::Debug for Connector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Connector")
            .field("server_name", &self.server_name)
            .finish_non_exhaustive()
    }
}

impl Connector {
    /// A client trusting `verify`, expecting the name `server_name` in the reader's
    /// certificate (default: the host of the address connected to). With
    /// [`Verify::Insecure`] a warning is logged.
    pub fn new(verify: &Verify, server_name: Option<&str>) -> Result<Connector, TlsError> {
        let config = client_config(verify)?;
        let server_name = server_name.map(parse_server_name).transpose()?;
        Ok(Connector {
            connector: TlsConnector::from(config),
            server_name,
        })
    }

    /// The name the reader's certificate must carry when connecting to `addr`
    /// (`HOST:PORT`, `[V6]:PORT` or `HOST`): the configured one, else the host.
    pub fn server_name(&self, addr: &str) -> Result<ServerName<'static>, TlsError> {
        match &self.server_name {
            Some(n) => Ok(n.clone()),
            None => parse_server_name(host_of(addr)),
        }
    }

    /// The TLS handshake over a connected `tcp` to `addr` (within [`HANDSHAKE_TIMEOUT`]).
    /// A failed handshake is an `io::Error` whose [`rustls_error`] says why, if rustls
    /// refused it.
    pub async fn connect(
        &self,
        addr: &str,
        tcp: TcpStream,
    ) -> io::Result<tokio_rustls::client::TlsStream<TcpStream>> {
        let name = self
            .server_name(addr)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))?;
        with_timeout(self.connector.connect(name, tcp)).await
    }
}

async fn with_timeout<T>(
    handshake: impl std::future::Future<Output = io::Result<T>>,
) -> io::Result<T> {
    tokio::time::timeout(HANDSHAKE_TIMEOUT, handshake)
        .await
        .unwrap_or_else(|_| {
            Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!("TLS handshake not done within {HANDSHAKE_TIMEOUT:?}"),
            ))
        })
}

/// The host part of `HOST:PORT`, `[V6]:PORT`, `V6` or `HOST`.
fn host_of(addr: &str) -> &str {
    if let Some(rest) = addr.strip_prefix('[') {
        return rest.split(']').next().unwrap_or(rest);
    }
    match addr.rsplit_once(':') {
        Some((host, _)) if !host.contains(':') => host,
        _ => addr,
    }
}

fn parse_server_name(name: &str) -> Result<ServerName<'static>, TlsError> {
    ServerName::try_from(name.to_string()).map_err(|_| TlsError::ServerName(name.to_string()))
}

/// The rustls error inside an I/O error from a handshake or a TLS stream, if it is one.
pub fn rustls_error(e: &io::Error) -> Option<&rustls::Error> {
    e.get_ref()?.downcast_ref::<rustls::Error>()
}

/// Whether a handshake failed over a certificate: this side refused the peer's, or the peer
/// refused this side's (an alert about a certificate).
pub fn is_certificate_error(e: &io::Error) -> bool {
    use rustls::AlertDescription as A;
    match rustls_error(e) {
        Some(rustls::Error::InvalidCertificate(_))
        | Some(rustls::Error::NoCertificatesPresented) => true,
        Some(rustls::Error::AlertReceived(a)) => matches!(
            a,
            A::BadCertificate
                | A::UnsupportedCertificate
                | A::CertificateRevoked
                | A::CertificateExpired
                | A::CertificateUnknown
                | A::UnknownCA
        ),
        _ => false,
    }
}

/// `--tls-ca`: WebPKI verification against the CA file's certificates (issuer chain, validity,
/// name); failing that, a server certificate byte-identical to one of them is accepted
/// (pinned: the user gave that very certificate).
#[derive(Debug)]
struct CaOrPinned {
    webpki: Arc<WebPkiServerVerifier>,
    pinned: Vec<CertificateDer<'static>>,
}

impl ServerCertVerifier for CaOrPinned {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        server_name: &ServerName<'_>,
        ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        match self.webpki.verify_server_cert(
            end_entity,
            intermediates,
            server_name,
            ocsp_response,
            now,
        ) {
            Ok(v) => Ok(v),
            Err(_) if self.pinned.iter().any(|c| c == end_entity) => {
                Ok(ServerCertVerified::assertion())
            }
            Err(e) => Err(e),
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.webpki.verify_tls12_signature(message, cert, dss)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.webpki.verify_tls13_signature(message, cert, dss)
    }

    fn supported_verify_schemes(&self) -> Vec<rustls::SignatureScheme> {
        self.webpki.supported_verify_schemes()
    }
}

/// `--tls-insecure`: accepts any server certificate; the handshake's signatures are still
/// verified with the provider's algorithms against the certificate presented.
#[derive(Debug)]
struct AnyCertificate(Arc<CryptoProvider>);

impl ServerCertVerifier for AnyCertificate {
    fn verify_server_cert(
        &self,
        _end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        _now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        Ok(ServerCertVerified::assertion())
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(
            message,
            cert,
            dss,
            &self.0.signature_verification_algorithms,
        )
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(
            message,
            cert,
            dss,
            &self.0.signature_verification_algorithms,
        )
    }

    fn supported_verify_schemes(&self) -> Vec<rustls::SignatureScheme> {
        self.0.signature_verification_algorithms.supported_schemes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_is_taken_from_every_address_form() {
        assert_eq!(host_of("reader.local:5085"), "reader.local");
        assert_eq!(host_of("reader.local"), "reader.local");
        assert_eq!(host_of("127.0.0.1:5085"), "127.0.0.1");
        assert_eq!(host_of("[::1]:5085"), "::1");
        assert_eq!(host_of("::1"), "::1");
    }

    #[test]
    fn bad_pem_files_are_named_with_the_reason() {
        let dir = tempfile::tempdir().expect("temp dir");
        let missing = dir.path().join("missing.pem");
        let e = load_certs(&missing).expect_err("no file");
        assert!(matches!(e, TlsError::Read { .. }), "{e}");
        assert!(e.to_string().contains("missing.pem"), "{e}");

        let empty = dir.path().join("empty.pem");
        std::fs::write(&empty, "not pem at all\n").expect("write");
        let e = load_certs(&empty).expect_err("no certificate");
        assert!(matches!(e, TlsError::NoCertificate { .. }), "{e}");
        assert!(e.to_string().contains("empty.pem"), "{e}");
        let e = load_key(&empty).expect_err("no key");
        assert!(matches!(e, TlsError::NoKey { .. }), "{e}");

        let cut = dir.path().join("cut.pem");
        std::fs::write(&cut, "-----BEGIN CERTIFICATE-----\nMIIB\n").expect("write");
        let e = load_certs(&cut).expect_err("cut");
        assert!(matches!(e, TlsError::Pem { .. }), "{e}");
        assert!(e.to_string().contains("cut.pem"), "{e}");

        let e = Connector::new(&Verify::Ca(empty.clone()), None).expect_err("no CA");
        assert!(matches!(e, TlsError::NoCertificate { .. }), "{e}");
        let Err(e) = acceptor(&missing, &empty) else {
            panic!("an acceptor without a certificate file");
        };
        assert!(e.to_string().contains("missing.pem"), "{e}");
    }

    #[test]
    fn a_server_name_must_be_a_name_or_an_address() {
        let c = Connector::new(&Verify::Insecure, None).expect("insecure connector");
        assert!(matches!(
            c.server_name("127.0.0.1:5085"),
            Ok(ServerName::IpAddress(_))
        ));
        assert!(matches!(
            c.server_name("reader.local:5085"),
            Ok(ServerName::DnsName(_))
        ));
        let e = Connector::new(&Verify::Insecure, Some("not a name!")).expect_err("bad name");
        assert!(matches!(e, TlsError::ServerName(_)), "{e}");
    }
}
