//! Bearer tokens, TLS and mutual TLS: friends get in, strangers do not. Certificates are made
//! fresh by rcgen for each test.

use std::path::PathBuf;

use landing_client::{ClientError, LandingClient, ServingStatus, TlsConfig};
use rcgen::{BasicConstraints, CertificateParams, CertifiedIssuer, IsCa, KeyPair};

use crate::support::{TestServer, landing, scratch, server_config};

/// A CA, and leaf certificates it signs.
struct Ca {
    issuer: CertifiedIssuer<'static, KeyPair>,
}

impl Ca {
    fn new(name: &str) -> Self {
        let mut params = CertificateParams::new(Vec::<String>::new()).expect("params");
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params
            .distinguished_name
            .push(rcgen::DnType::CommonName, name);
        let issuer =
            CertifiedIssuer::self_signed(params, KeyPair::generate().expect("key")).expect("CA");
        Self { issuer }
    }

    fn pem(&self) -> Vec<u8> {
        self.issuer.pem().into_bytes()
    }

    /// (certificate PEM, key PEM) for `names`.
    fn leaf(&self, names: &[&str]) -> (Vec<u8>, Vec<u8>) {
        let params =
            CertificateParams::new(names.iter().map(|s| s.to_string()).collect::<Vec<_>>())
                .expect("params");
        let key = KeyPair::generate().expect("key");
        let cert = params.signed_by(&key, &self.issuer).expect("sign");
        (cert.pem().into_bytes(), key.serialize_pem().into_bytes())
    }
}

fn write(name: &str, bytes: &[u8]) -> PathBuf {
    let p = scratch().join(format!("{}-{name}", std::process::id()));
    std::fs::write(&p, bytes).expect("write");
    p
}

/// A unique file name per test, so parallel tests do not overwrite each other's files.
fn unique(tag: &str, name: &str) -> String {
    format!("{tag}-{name}")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tokens_let_friends_in_and_keep_strangers_out() {
    let mut config = server_config();
    config.auth.tokens_file = write(&unique("auth", "tokens"), b"# fleet\nalpha-token\n");
    let server = TestServer::with_config(config).await;

    let anonymous = server.client().await;
    let err = anonymous.info().await.unwrap_err();
    assert_eq!(err.code(), Some(tonic::Code::Unauthenticated), "{err}");
    // Health is exempt, so orchestrators can probe without a token.
    assert_eq!(
        anonymous.health("").await.expect("health"),
        ServingStatus::Serving
    );

    let wrong = LandingClient::connect(server.client_config().with_token("beta-token"))
        .await
        .expect("connect");
    assert_eq!(
        wrong.info().await.unwrap_err().code(),
        Some(tonic::Code::Unauthenticated)
    );

    let friend = LandingClient::connect(server.client_config().with_token("alpha-token"))
        .await
        .expect("connect");
    assert!(
        !friend
            .info()
            .await
            .expect("info with the token")
            .version
            .is_empty()
    );

    // The CLI maps a refusal to exit 6 and takes the token from --token.
    assert_eq!(
        landing(&["--server", &server.url, "info"]).await.0,
        landing_cli::exit::AUTH
    );
    assert_eq!(
        landing(&["--server", &server.url, "--token", "alpha-token", "info"])
            .await
            .0,
        0
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_serves_clients_that_trust_the_ca_only() {
    let ca = Ca::new("landing test CA");
    let (cert, key) = ca.leaf(&["localhost"]);
    let mut config = server_config();
    config.tls.cert_path = write(&unique("tls", "server.pem"), &cert);
    config.tls.key_path = write(&unique("tls", "server.key"), &key);
    let server = TestServer::with_config(config).await;
    let trusting = TlsConfig {
        ca_cert_pem: Some(ca.pem()),
        domain_name: Some("localhost".into()),
        ..Default::default()
    };

    let friend = LandingClient::connect(server.client_config().with_tls(trusting))
        .await
        .expect("TLS connect");
    assert!(
        !friend
            .info()
            .await
            .expect("info over TLS")
            .version
            .is_empty()
    );

    let stranger_ca = Ca::new("someone else");
    let distrusting = TlsConfig {
        ca_cert_pem: Some(stranger_ca.pem()),
        domain_name: Some("localhost".into()),
        ..Default::default()
    };
    let err = match LandingClient::connect(server.client_config().with_tls(distrusting)).await {
        Ok(c) => c.info().await.unwrap_err(),
        Err(e) => e,
    };
    assert!(
        err.is_unreachable(),
        "a certificate from an unknown CA is refused: {err}"
    );

    // Plain HTTP/2 to the TLS port gets nowhere.
    let plain = server.url.replacen("https://", "http://", 1);
    let err = match LandingClient::connect(landing_client::ClientConfig::new(plain)).await {
        Ok(c) => c.info().await.unwrap_err(),
        Err(e) => e,
    };
    assert!(
        matches!(
            err,
            ClientError::Unreachable { .. } | ClientError::Status(_)
        ),
        "{err}"
    );

    // The CLI with --ca-cert and --tls-domain.
    let ca_path = write(&unique("tls", "ca.pem"), &ca.pem());
    let ca_arg = ca_path.to_str().expect("path");
    let (code, out) = landing(&[
        "--server",
        &server.url,
        "--ca-cert",
        ca_arg,
        "--tls-domain",
        "localhost",
        "info",
        "--json",
    ])
    .await;
    assert_eq!(code, 0, "{out}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mutual_tls_requires_a_client_certificate_from_the_client_ca() {
    let server_ca = Ca::new("server CA");
    let client_ca = Ca::new("client CA");
    let (cert, key) = server_ca.leaf(&["localhost"]);
    let mut config = server_config();
    config.tls.cert_path = write(&unique("mtls", "server.pem"), &cert);
    config.tls.key_path = write(&unique("mtls", "server.key"), &key);
    config.tls.client_ca_path = write(&unique("mtls", "client-ca.pem"), &client_ca.pem());
    let server = TestServer::with_config(config).await;
    let tls = |identity: Option<(Vec<u8>, Vec<u8>)>| TlsConfig {
        ca_cert_pem: Some(server_ca.pem()),
        client_cert_pem: identity.as_ref().map(|i| i.0.clone()),
        client_key_pem: identity.map(|i| i.1),
        domain_name: Some("localhost".into()),
    };
    let attempt = |tls: TlsConfig| {
        let config = server.client_config().with_tls(tls);
        async move {
            match LandingClient::connect(config).await {
                Ok(c) => c.info().await.map(|_| ()),
                Err(e) => Err(e),
            }
        }
    };

    attempt(tls(Some(client_ca.leaf(&["drone-7"]))))
        .await
        .expect("a client certificate from the client CA");
    assert!(attempt(tls(None)).await.is_err(), "no client certificate");
    assert!(
        attempt(tls(Some(Ca::new("rogue").leaf(&["drone-x"]))))
            .await
            .is_err(),
        "a stranger's certificate"
    );
    server.stop().await;
}
