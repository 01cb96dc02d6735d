//! Database faults answer 503, never 500 (issue 29, point 1). Every backend connection of a
//! live server's PostgreSQL database is terminated again and again while readers browse the
//! boards, pages and API and `poseboard submit` uploads: no answer is a 500, a 503 carries
//! `Retry-After` and says nothing was changed, each upload ends done once with the scores
//! `poseboard eval` gives, and the log names the outage once, not once per failed request.
//! PostgreSQL only: terminating connections is its operation.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::common::{
    Answer, Db, TestDb, assert_200_or_503, cli_report, column, fixtures, pg_exec, read_until,
    reference_datasets, start, submit_and_wait, upload, wait_done,
};
use serde_json::Value;

#[test]
fn terminated_connections_answer_503_never_500() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(Db::Postgres, "faults");
    let url = db.url().expect("PostgreSQL");
    let server = start(&data, &datasets, &db, &["--no-demo"]);
    let base = server.base.clone();
    let first = fixtures().join("results/noisesmall_synthA-test.csv");
    let r = upload(&server, "steady", "synthA", &first, None);
    assert_eq!(r.status(), 202);
    let seeded = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(&base, seeded, Duration::from_secs(120));

    let paths = [
        "/api/v1/submissions".to_string(),
        "/api/v1/leaderboards/bop19?dataset=synthA".to_string(),
        "/leaderboards/bop19?dataset=synthA".to_string(),
        format!("/submissions/{seeded}"),
        format!("/api/v1/submissions/{seeded}"),
        "/api/v1/methods".to_string(),
    ];
    let stop = AtomicBool::new(false);
    let answers: Mutex<Vec<Answer>> = Mutex::new(Vec::new());
    let mut terminated = 0;
    let files = ["noisemedium", "gtexact", "symflip"];
    let submitted: Vec<(String, Value)> = std::thread::scope(|s| {
        let killer = s.spawn(|| {
            let mut rounds = 0;
            while !stop.load(Ordering::Relaxed) {
                pg_exec(
                    &url,
                    "SELECT pg_terminate_backend(pid) FROM pg_stat_activity \
                     WHERE datname = current_database() AND pid <> pg_backend_pid()",
                );
                rounds += 1;
                std::thread::sleep(Duration::from_millis(250));
            }
            rounds
        });
        for reader in 0..3 {
            let (paths, stop, answers, base) = (&paths, &stop, &answers, &base);
            s.spawn(move || read_until(base, paths, reader, Duration::ZERO, stop, answers));
        }
        let submitted = files
            .iter()
            .map(|name| {
                let file = fixtures().join(format!("results/{name}_synthA-test.csv"));
                let printed = submit_and_wait(&server, &file, name, "synthA");
                (name.to_string(), printed)
            })
            .collect();
        stop.store(true, Ordering::Relaxed);
        terminated = killer.join().expect("killer");
        submitted
    });
    assert!(terminated > 3, "connections terminated {terminated} times");

    let answers = answers.into_inner().expect("answers");
    assert!(answers.len() > 50, "only {} reads", answers.len());
    assert_200_or_503(&answers);

    // Each upload ended done once, with the scores of `poseboard eval`.
    let synth_a = datasets.join("synthA");
    for (name, printed) in &submitted {
        assert_eq!(printed["status"], "done", "{name}");
        let id = printed["id"].as_i64().expect("id");
        let file = fixtures().join(format!("results/{name}_synthA-test.csv"));
        let report = cli_report(&synth_a, &file, "bop19");
        for key in ["bop19_average_recall", "obj_average_recalls"] {
            assert_eq!(printed["scores"]["bop19"][key], report[key], "{name} {key}");
        }
        let rows = column(
            &db,
            &data,
            &format!(
                "SELECT CAST(COUNT(*) AS TEXT) FROM submissions WHERE method_id = \
                 (SELECT method_id FROM submissions WHERE id = {id})"
            ),
        );
        assert_eq!(rows, ["1"], "{name}: one submission");
    }

    // One line when an outage begins and one when it ends, not one per failed request.
    let failed = answers.iter().filter(|a| a.status == 503).count();
    let log = std::fs::read_to_string(data.join("server.log")).expect("log");
    let begun = log.matches("answering 503 until it is back").count();
    let ended = log.matches("the database answers again").count();
    assert_eq!(log.matches("request failed").count(), 0, "{log}");
    assert!(
        failed == 0 || begun >= 1,
        "{failed} answers 503 and no outage logged"
    );
    assert!(
        begun <= ended + 1,
        "{begun} outages begun and {ended} ended: logged per request"
    );
}
