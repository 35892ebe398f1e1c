//! `landing eval --catalog` against a real server with a catalog in a fresh SQLite file, over a
//! tiny revisit set written by the simulator: one check per approach, a table per visit whose
//! counts agree with the sites the checks list (unsafe and distinct sites) and the stale sites
//! followed, recall in [0, 1], the report files written; a second run on the same catalog is
//! refused as not fresh.

use landing_cli::exit;
use landing_server::Config;
use landing_sim::flight::FlightConfig;
use landing_sim::recording::RecordConfig;
use landing_sim::revisit::ChangeRates;
use landing_sim::scenarios::{Origin, Revisits, ScenarioConfig, write_scenarios};
use serde_json::Value;

use crate::support::{TestServer, landing, scratch, server_config};

/// A server whose catalog is the new SQLite file `name` in the scratch directory, writing at once.
fn catalog_config(name: &str) -> Config {
    let mut c = server_config();
    c.catalog.enabled = true;
    c.catalog.path = scratch().join(name);
    let _ = std::fs::remove_file(&c.catalog.path);
    c.catalog.flush_interval_s = 0.05;
    c.catalog.observe_interval_s = 0.0;
    c
}

/// One world, one building, 6 frames per approach, visited twice; frames with an origin.
fn revisit_set(dir: &std::path::Path) {
    let _ = std::fs::remove_dir_all(dir);
    let config = ScenarioConfig {
        seed: 6101,
        worlds: 1,
        buildings: 1,
        record: RecordConfig {
            flight: FlightConfig {
                frames: 6,
                ..Default::default()
            },
            ..Default::default()
        },
        origin: Origin::Manhattan,
        revisits: Some(Revisits {
            count: 1,
            interval_s: 3600.0,
            rates: ChangeRates::default(),
        }),
    };
    write_scenarios(&config, dir).expect("write the revisit set");
}

fn count(v: &Value) -> usize {
    v.as_u64().expect("a count") as usize
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn eval_catalog_scores_every_visit_and_refuses_a_used_catalog() {
    let set = scratch().join("evalcat-set");
    revisit_set(&set);
    let server = TestServer::with_config(catalog_config("evalcat.sqlite")).await;
    let out = scratch().join("evalcat-out");
    let (set_s, out_s) = (set.to_string_lossy(), out.to_string_lossy());
    let args = [
        "--server",
        &server.url,
        "--json",
        "eval",
        &set_s,
        "--catalog",
        "--modes",
        "truth",
        "--gate",
        "truth",
        "--catalog-wait",
        "2",
        "--out",
        &out_s,
    ];
    let (code, stdout) = landing(&args).await;
    let v: Value = serde_json::from_str(&stdout).expect("json");
    let checks = v["checks"].as_array().expect("checks");
    assert_eq!(checks.len(), 2, "one check after each approach: {v:#}");
    let scores: Vec<&Value> = checks
        .iter()
        .flat_map(|c| c["sites"].as_array().expect("sites"))
        .collect();
    let distinct = |class: Option<&str>| {
        let mut keys: Vec<String> = scores
            .iter()
            .filter(|s| class.is_none_or(|c| s["class"] == c))
            .map(|s| format!("{}/{}/{}", s["world"], s["site_id"], s["first_seen_ms"]))
            .collect();
        keys.sort();
        keys.dedup();
        keys.len()
    };
    let all = &v["overall"];
    assert_eq!(
        count(&all["unsafe_sites"]),
        distinct(Some("unsafe")),
        "{v:#}"
    );
    assert_eq!(count(&all["sites"]), distinct(None), "{v:#}");
    let stale = v["stale"].as_array().expect("stale");
    assert_eq!(count(&all["stale"]), stale.len(), "{v:#}");
    let want = if count(&all["unsafe_sites"]) > 0 {
        7
    } else {
        exit::OK
    };
    assert_eq!(code, want, "{v:#}");
    let per_visit = v["per_visit"].as_array().expect("per_visit");
    assert_eq!(per_visit.len(), 2, "visits 0 and 1: {v:#}");
    for (k, row) in per_visit.iter().enumerate() {
        assert_eq!(count(&row["visit_index"]), k);
        assert_eq!(count(&row["approaches"]), 1);
        assert_eq!(count(&row["failed_frames"]), 0, "{v:#}");
        let (found, landable) = (count(&row["found_roofs"]), count(&row["landable_roofs"]));
        assert!(
            found <= landable && landable <= 1,
            "recall in [0, 1]: {row:#}"
        );
    }
    // The first visit cannot be stale: nothing was confirmed before it.
    assert_eq!(count(&per_visit[0]["stale"]), 0, "{v:#}");
    assert!(out.join("catalog.md").is_file() && out.join("catalog.json").is_file());
    if !scores.is_empty() {
        let (again, _) = landing(&args).await;
        assert_eq!(again, exit::ERROR, "a used catalog is refused");
    }
    server.stop().await;
}
