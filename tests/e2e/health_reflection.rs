//! Standard health checking and server reflection, both reflection versions: v1 for current
//! tools, v1alpha for the stock Python client (`grpcio-reflection`) and older tools. The Python
//! client itself runs against a real server in `scripts/test.sh`
//! (`client/examples/python/reflect.py`).

use landing_client::ServingStatus;
use tokio_stream::StreamExt;
use tonic::transport::Channel;

use crate::support::TestServer;

/// Every service the server serves, as reflection must list it.
const SERVICES: [&str; 4] = [
    "landing.v1.LandingService",
    "grpc.health.v1.Health",
    "grpc.reflection.v1.ServerReflection",
    "grpc.reflection.v1alpha.ServerReflection",
];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_reports_serving() {
    let server = TestServer::start().await;
    let client = server.client().await;
    assert_eq!(
        client.health("").await.expect("health"),
        ServingStatus::Serving
    );
    assert_eq!(
        client
            .health("landing.v1.LandingService")
            .await
            .expect("health"),
        ServingStatus::Serving
    );
    server.stop().await;
}

async fn channel(server: &TestServer) -> Channel {
    tonic::transport::Endpoint::from_shared(server.url.clone())
        .expect("url")
        .connect()
        .await
        .expect("connect")
}

/// What one reflection version answers to: list the services, the file of
/// `landing.v1.LandingService`, and the file of a symbol that does not exist.
struct Answers {
    services: Vec<String>,
    files: Vec<prost_types::FileDescriptorProto>,
    unknown_symbol_code: tonic::Code,
}

/// The three requests of [`Answers`] over one call of the v1 or v1alpha service: the two
/// versions have the same messages in different packages, so one body serves both.
macro_rules! ask {
    ($version:ident, $channel:expr) => {{
        use prost::Message as _;
        use tonic_reflection::pb::$version::ServerReflectionRequest;
        use tonic_reflection::pb::$version::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::$version::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::$version::server_reflection_response::MessageResponse;
        let request = |m| ServerReflectionRequest {
            host: String::new(),
            message_request: Some(m),
        };
        let requests = vec![
            request(MessageRequest::ListServices(String::new())),
            request(MessageRequest::FileContainingSymbol(
                "landing.v1.LandingService".into(),
            )),
            request(MessageRequest::FileContainingSymbol(
                "landing.v1.NoSuchService".into(),
            )),
        ];
        let mut answers = ServerReflectionClient::new($channel)
            .server_reflection_info(tokio_stream::iter(requests))
            .await
            .expect(concat!("reflection ", stringify!($version), " is served"))
            .into_inner();
        let mut got = Vec::new();
        while let Some(answer) = answers.next().await {
            got.push(answer);
        }
        let [list, files, unknown]: [_; 3] = got.try_into().expect("one answer per request");
        let Some(MessageResponse::ListServicesResponse(list)) = list.expect("ok").message_response
        else {
            panic!("no service list")
        };
        let Some(MessageResponse::FileDescriptorResponse(files)) =
            files.expect("ok").message_response
        else {
            panic!("no file descriptors")
        };
        // tonic-reflection ends the call with the status rather than an ErrorResponse.
        let unknown = unknown.expect_err("an unknown symbol is an error");
        Answers {
            services: list.service.into_iter().map(|s| s.name).collect(),
            files: files
                .file_descriptor_proto
                .iter()
                .map(|b| prost_types::FileDescriptorProto::decode(b.as_slice()).expect("decode"))
                .collect(),
            unknown_symbol_code: unknown.code(),
        }
    }};
}

fn check(version: &str, answers: &Answers) {
    for service in SERVICES {
        assert!(
            answers.services.iter().any(|s| s == service),
            "{version} lists {service}: {:?}",
            answers.services
        );
    }
    let landing = answers
        .files
        .iter()
        .find(|f| f.package() == "landing.v1")
        .unwrap_or_else(|| panic!("{version}: no landing.v1 file"));
    let methods: Vec<&str> = landing
        .service
        .iter()
        .find(|s| s.name() == "LandingService")
        .expect("the service is in its file")
        .method
        .iter()
        .map(|m| m.name())
        .collect();
    assert!(
        methods.contains(&"DetectLandingSites") && methods.contains(&"StreamLandingSites"),
        "{version}: {methods:?}"
    );
    assert_eq!(
        answers.unknown_symbol_code,
        tonic::Code::NotFound,
        "{version}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reflection_v1_lists_the_services_and_describes_the_api() {
    let server = TestServer::start().await;
    let answers = ask!(v1, channel(&server).await);
    check("v1", &answers);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reflection_v1alpha_lists_the_services_and_describes_the_api() {
    let server = TestServer::start().await;
    let answers = ask!(v1alpha, channel(&server).await);
    check("v1alpha", &answers);
    server.stop().await;
}
