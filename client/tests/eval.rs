//! Development harness: compiles the eval module as part of this test crate.
#[path = "../src/eval/mod.rs"]
mod eval;
pub use landing_client::*;

// DEV ONLY (removed before hand-off): runs the evaluation against EVAL_DEV_SERVER.
#[test]
fn dev_run() {
    let Ok(server) = std::env::var("EVAL_DEV_SERVER") else { return };
    let files: Vec<std::path::PathBuf> = std::env::var("EVAL_DEV_FILES").unwrap().split(',').map(Into::into).collect();
    let conn = landing_client::cli::ConnectionArgs {
        server,
        token: None,
        ca_cert: None,
        client_cert: None,
        client_key: None,
        tls_domain: None,
        connect_timeout: 5.0,
        timeout: 60.0,
    };
    let args = eval::cli::EvalArgs {
        recordings: files,
        out: std::env::var("EVAL_DEV_OUT").unwrap_or("/tmp/evalscratch/out".into()).into(),
        modes: eval::Mode::ALL.to_vec(),
        gate: vec![eval::Mode::Model],
        limit: 0,
        cell: 0.05,
        min_truth_radius: 1.0,
        polylabel_precision: None,
        max_sites: None,
        overlays: true,
    };
    let rt = tokio::runtime::Runtime::new().unwrap();
    let mut out = Vec::new();
    let code = rt.block_on(eval::cli::eval_cmd(&conn, &args, false, &mut out)).map_err(|e| e.message).unwrap();
    println!("{}\nexit {code}", String::from_utf8_lossy(&out));
}
