//! The `horizon-client` binary against the real service in process: `cut` (summary and
//! `--json`, the server's body as sent), `stream` (every message checked against a fresh cut),
//! `walk` (`--json` report), and one-line errors with status 1.

mod common;

use std::process::{Command, Output};

use common::{serve, world, TempDir, EXTENT};
use horizon_client::Client;
use horizon_protocol::{CutResponse, View};
use horizon_server::service::Config;

/// Runs the binary with `args`, off the async runtime.
async fn client(args: Vec<String>) -> Output {
    tokio::task::spawn_blocking(move || {
        Command::new(env!("CARGO_BIN_EXE_horizon-client"))
            .args(&args)
            .output()
            .expect("the binary runs")
    })
    .await
    .expect("the command's task")
}

fn args(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| (*s).to_owned()).collect()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// The command failed with status 1 and one line on stderr.
#[track_caller]
fn assert_one_line_error(out: &Output) {
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let err = text(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err:?}");
    assert!(err.starts_with("horizon-client: error: "), "{err:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_commands_run_against_the_service() {
    let dir = TempDir::new("cli");
    let (world, _) = world(&dir);
    let server = serve(
        &world,
        Config {
            rebuild: false,
            ..Config::default()
        },
    )
    .await;
    let base = server.base.clone();
    let centre = format!("{},3,{}", EXTENT / 2.0, EXTENT / 2.0);

    // cut: a summary, and the body as sent.
    let out = client(args(&["cut", &base, "--eye", &centre])).await;
    assert!(out.status.success(), "{out:?}");
    let summary = text(&out.stdout);
    assert!(summary.contains("objects in"), "{summary}");
    assert!(summary.contains("complete: yes"), "{summary}");
    let out = client(args(&[
        "cut",
        &base,
        "--eye",
        &centre,
        "--max-entries",
        "20",
        "--json",
    ]))
    .await;
    assert!(out.status.success(), "{out:?}");
    let printed: CutResponse = serde_json::from_slice(&out.stdout).expect("a cut on stdout");
    let mut view = View::at([EXTENT / 2.0, 3.0, EXTENT / 2.0]);
    view.budgets.max_entries = Some(20);
    let fresh = Client::new(&base)
        .expect("a client")
        .cut(&view)
        .await
        .expect("a cut");
    assert_eq!(printed, fresh);
    assert!(printed.entries.len() <= 20);

    // stream: from outside the grid (a negative coordinate) inwards, every message checked;
    // every node as its aggregate, so that walking in refines them (with instances this
    // grid of three reused boxes is two entries from anywhere).
    let out = client(args(&[
        "stream",
        &base,
        "--eye",
        "-40,5,48",
        "--steps",
        "8",
        "--step",
        "12",
        "--wait",
        "0.5",
        "--no-instances",
        "--json",
    ]))
    .await;
    assert!(out.status.success(), "{out:?}");
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("a report");
    assert_eq!(report["resets"], 1, "{report}");
    assert!(report["compared"].as_u64() >= Some(2), "{report}");
    assert_eq!(report["skipped"], 0, "{report}");

    // walk: a JSON report.
    let path_file = dir.0.join("path.json");
    std::fs::write(
        &path_file,
        format!("[[-20, 4, -20], [{EXTENT}, 4, {EXTENT}]]"),
    )
    .expect("the path file");
    let out = client(args(&[
        "walk",
        &base,
        "--path",
        &path_file.to_string_lossy(),
        "--speed",
        "30",
        "--duration",
        "1.5",
        "--json",
    ]))
    .await;
    assert!(out.status.success(), "{out:?}");
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("a report");
    assert_eq!(report["resets"], 1, "{report}");
    assert!(report["bytes_fetched"].as_u64() > Some(0), "{report}");

    // The summaries people read.
    let out = client(args(&[
        "stream", &base, "--eye", "-40,5,48", "--steps", "3", "--step", "20", "--wait", "0.5",
    ]))
    .await;
    assert!(out.status.success(), "{out:?}");
    let stream_summary = text(&out.stdout);
    assert!(
        stream_summary.contains("compared equal"),
        "{stream_summary}"
    );
    let out = client(args(&[
        "walk",
        &base,
        "--path",
        &path_file.to_string_lossy(),
        "--duration",
        "1",
        "--bandwidth",
        "100000",
    ]))
    .await;
    assert!(out.status.success(), "{out:?}");
    let walk_summary = text(&out.stdout);
    assert!(
        walk_summary.contains("frames with a drawn entry missing"),
        "{walk_summary}"
    );
    eprintln!("{summary}{stream_summary}{walk_summary}");

    // Errors: one line, status 1.
    assert_one_line_error(&client(args(&["cut", &base, "--eye", "1,2"])).await);
    assert_one_line_error(
        &client(args(&[
            "cut",
            &base,
            "--eye",
            "0,0,0",
            "--min-solid-angle",
            "20",
        ]))
        .await,
    );
    assert_one_line_error(&client(args(&["cut", "http://127.0.0.1:1", "--eye", "0,0,0"])).await);
    assert_one_line_error(
        &client(args(&[
            "walk",
            &base,
            "--path",
            &dir.0.join("missing.json").to_string_lossy(),
        ]))
        .await,
    );
}
