//! TLS and client certificates over loopback. Test certificates are made with the `openssl`
//! command line at test time (no key material is committed).

use std::path::{Path, PathBuf};
use std::process::Command;

use landing_proto::v1;
use landing_proto::v1::landing_service_client::LandingServiceClient;
use landing_server::{Config, start};
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Identity};

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .current_dir(dir)
        .args(args)
        .output()
        .expect("the openssl command");
    assert!(
        out.status.success(),
        "openssl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A CA, a server certificate for localhost/127.0.0.1 and a client certificate, all signed by it.
fn certificates() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-tls-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ec = [
        "-newkey",
        "ec",
        "-pkeyopt",
        "ec_paramgen_curve:prime256v1",
        "-nodes",
    ];
    openssl(
        &dir,
        &[
            &["req", "-x509"][..],
            &ec,
            &[
                "-keyout",
                "ca.key",
                "-out",
                "ca.pem",
                "-days",
                "2",
                "-subj",
                "/CN=test-ca",
            ],
        ]
        .concat(),
    );
    for (name, usage, san) in [
        (
            "server",
            "serverAuth",
            "subjectAltName=DNS:localhost,IP:127.0.0.1\n",
        ),
        ("client", "clientAuth", ""),
    ] {
        let ext = format!(
            "{san}basicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage={usage}\n"
        );
        std::fs::write(dir.join(format!("{name}.ext")), ext).unwrap();
        let (key, csr, pem, extfile) = (
            format!("{name}.key"),
            format!("{name}.csr"),
            format!("{name}.pem"),
            format!("{name}.ext"),
        );
        openssl(
            &dir,
            &[
                &["req"][..],
                &ec,
                &[
                    "-keyout",
                    &key,
                    "-out",
                    &csr,
                    "-subj",
                    &format!("/CN={name}"),
                ],
            ]
            .concat(),
        );
        openssl(
            &dir,
            &[
                "x509",
                "-req",
                "-in",
                &csr,
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca.key",
                "-CAcreateserial",
                "-out",
                &pem,
                "-days",
                "2",
                "-extfile",
                &extfile,
            ],
        );
    }
    dir
}

fn config(dir: &Path, client_ca: bool) -> Config {
    let mut c = Config::default();
    c.segmentation.enabled = false;
    c.catalog.enabled = false;
    c.server.metrics_listen = String::new();
    c.tls.cert_path = dir.join("server.pem");
    c.tls.key_path = dir.join("server.key");
    if client_ca {
        c.tls.client_ca_path = dir.join("ca.pem");
    }
    c
}

async fn call(
    addr: std::net::SocketAddr,
    dir: &Path,
    with_identity: bool,
) -> Result<v1::ServiceInfo, String> {
    let ca = Certificate::from_pem(std::fs::read(dir.join("ca.pem")).unwrap());
    let mut tls = ClientTlsConfig::new()
        .ca_certificate(ca)
        .domain_name("localhost");
    if with_identity {
        let cert = std::fs::read(dir.join("client.pem")).unwrap();
        let key = std::fs::read(dir.join("client.key")).unwrap();
        tls = tls.identity(Identity::from_pem(cert, key));
    }
    let channel = Channel::from_shared(format!("https://localhost:{}", addr.port()))
        .unwrap()
        .tls_config(tls)
        .map_err(|e| e.to_string())?
        .connect()
        .await
        .map_err(|e| format!("connect: {e}"))?;
    LandingServiceClient::new(channel)
        .get_service_info(v1::GetServiceInfoRequest {})
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| s.to_string())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_with_and_without_client_certificates() {
    let dir = certificates();

    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let server = start(config(&dir, false), listener).await.unwrap();
    let info = call(server.addr, &dir, false).await.unwrap();
    assert_eq!(info.classes.len(), 15);
    server.shutdown().await.unwrap();

    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let server = start(config(&dir, true), listener).await.unwrap();
    assert!(
        call(server.addr, &dir, false).await.is_err(),
        "a client without a certificate got in"
    );
    call(server.addr, &dir, true).await.unwrap();
    server.shutdown().await.unwrap();
}
