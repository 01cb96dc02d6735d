//! The store's own conformance suite: every operation of `server::store::Store` run against a
//! fresh SQLite file and a fresh PostgreSQL database, so that the two backends behave the same
//! (typed rows, unique violations, transactions under concurrency, corrupt values refused).

use std::path::Path;
use std::sync::atomic::AtomicBool;

use crate::common::{Db, TestDb, both_databases, fixtures};
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::{Dataset, NoProgress, evaluate, results::load_results};
use server::domain::{
    BoardProtocol, DatasetId, DatasetName, GroupName, Hardware, MethodDetails, MethodName,
    Modality, SubmissionId, Task, TeamName, TokenLabel, UserId, UserName, Visibility,
};
use server::preflight::Preflight;
use server::store::accounts::Counter;
use server::store::audit::AdminAction;
use server::store::board_rows::Whose;
use server::store::datasets::DatasetRow;
use server::store::methods::MethodMeta;
use server::store::pose_errors::NewErrors;
use server::store::preparations::{PreparationRow, PreparationState};
use server::store::queue::Finished;
use server::store::submissions::{Created, FairUse, Fault, NewSubmission, QueuePlace, Status};
use server::store::{Store, StoreError};

/// A migrated store on a fresh database of `kind`, with its URL (for raw SQL).
async fn store(kind: Db, db: &TestDb, dir: &Path) -> (Store, String) {
    let url = db.url().unwrap_or_else(|| server::store::sqlite_url(dir));
    let _ = kind;
    let store = Store::connect(&url).await.expect("connects");
    store.migrate().await.expect("migrates");
    (store, url)
}

fn run(body: impl std::future::Future<Output = ()>) {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(4)
        .enable_all()
        .build()
        .expect("runtime")
        .block_on(body);
}

async fn raw(url: &str, sql: &str) {
    sqlx::any::install_default_drivers();
    let pool = sqlx::AnyPool::connect(url).await.expect("raw connection");
    sqlx::query(sqlx::AssertSqlSafe(sql.to_string()))
        .execute(&pool)
        .await
        .expect("raw statement");
    pool.close().await;
}

fn dataset_row(name: &str) -> DatasetRow {
    DatasetRow {
        id: DatasetId::new(0),
        name: name.to_string(),
        path: fixtures().join("dataset").display().to_string(),
        objects_count: 4,
        scenes_count: 2,
        images_count: 8,
        targets_count: 28,
        instances_count: 33,
        image_width: 640,
        image_height: 480,
        added_at: 0,
        retired: false,
        content_hash: Some("c0ffee".to_string()),
        core: None,
    }
}

async fn user(store: &Store, name: &str) -> UserId {
    store
        .create_user(
            &UserName::parse(name).unwrap(),
            "$argon2id$not-a-real-hash",
            false,
        )
        .await
        .expect("user created")
}

struct Fixture {
    method: MethodName,
    meta: MethodMeta,
    hardware: Hardware,
    preflight: Preflight,
}

fn fixture(method: &str) -> Fixture {
    Fixture {
        method: MethodName::parse(method).unwrap(),
        meta: MethodMeta {
            modality: Some(Modality::RgbD),
            ..MethodMeta::default()
        },
        hardware: Hardware::parse("a GPU").unwrap(),
        preflight: Preflight {
            estimates: 35,
            warnings: vec!["1 estimate is ignored".into()],
            ..Preflight::default()
        },
    }
}

fn new_submission<'a>(
    f: &'a Fixture,
    owner_id: UserId,
    dataset_id: DatasetId,
    sha: &'a str,
    protocols: &'a [ProtocolName],
) -> NewSubmission<'a> {
    NewSubmission {
        owner_id,
        team_id: None,
        method: &f.method,
        meta: &f.meta,
        dataset_id,
        protocols,
        task: None,
        visibility: Visibility::Public,
        file_name: "m_synthA-test.csv",
        file_sha256: sha,
        file_size: 1234,
        file_gzip: &[31, 139, 8],
        estimates_count: 35,
        hardware: &f.hardware,
        preflight: &f.preflight,
        held: false,
    }
}

/// A finished evaluation of the reference file: its reports, with the per-estimate errors of
/// each protocol as the worker stores them.
fn finished(protocols: &[ProtocolName]) -> (Finished, Vec<serde_json::Value>) {
    let dataset = Dataset::load(&fixtures().join("dataset")).expect("reference dataset");
    let results = load_results(&fixtures().join("results/noisemedium_synthA-test.csv"))
        .expect("reference results");
    let mut reports = Vec::new();
    let mut errors = Vec::new();
    let mut first_rows = Vec::new();
    for &p in protocols {
        let evaluation = evaluate(
            &dataset,
            &results,
            &Protocol::named(p),
            &NoProgress,
            &AtomicBool::new(false),
        )
        .expect("evaluates");
        let rows = evaluation.error_rows();
        let json = serde_json::to_vec(&rows).expect("json");
        errors.push(NewErrors {
            protocol: p,
            rows_count: rows.len() as i64,
            gzip: server::datasets::uploaded_file::compress(&json).expect("gzip"),
        });
        if first_rows.is_empty() {
            first_rows = rows;
        }
        reports.push(evaluation.report);
    }
    let done = Finished {
        reports,
        errors,
        replicates: Default::default(),
        eval_ms: 1000,
        dataset_hash: "store-test".to_string(),
    };
    (done, first_rows)
}

fn datasets_stay_retired(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let db = TestDb::new(kind, "store_datasets");
    run(async {
        let (store, _) = store(kind, &db, dir.path()).await;
        let row = store
            .register_dataset(&dataset_row("synthA"))
            .await
            .unwrap();
        assert!(!row.retired);
        assert_eq!(store.datasets().await.unwrap(), vec![row.clone()]);
        assert!(store.retire_dataset("synthA").await.unwrap());
        assert!(!store.retire_dataset("synthA").await.unwrap());
        // Registering again (a restart) keeps it retired.
        let again = store
            .register_dataset(&dataset_row("synthA"))
            .await
            .unwrap();
        assert_eq!(again.id, row.id);
        assert!(again.retired);
        assert!(store.datasets().await.unwrap().is_empty());
        assert!(store.dataset_by_name("synthA").await.unwrap().is_none());
        assert!(
            store
                .dataset(row.id)
                .await
                .unwrap()
                .is_some_and(|d| d.retired)
        );
        assert!(store.revive_dataset("synthA").await.unwrap());
        assert_eq!(
            store.dataset_by_name("synthA").await.unwrap().map(|d| d.id),
            Some(row.id)
        );
    });
}
both_databases!(datasets_stay_retired);

fn submissions_queue_and_scores(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let db = TestDb::new(kind, "store_lifecycle");
    let (done_job, error_rows) = finished(&[ProtocolName::Bop19, ProtocolName::Eccv18]);
    let reports = done_job.reports.clone();
    run(async {
        let (store, _) = store(kind, &db, dir.path()).await;
        let ds = store
            .register_dataset(&dataset_row("synthA"))
            .await
            .unwrap();
        let owner = user(&store, "alice").await;
        let f = fixture("CosyPose");
        let protocols = [ProtocolName::Bop19, ProtocolName::Eccv18];
        let new = new_submission(&f, owner, ds.id, "aaaa", &protocols);
        let Created::New(id) = store.create_submission(&new, None).await.unwrap() else {
            panic!("a new submission");
        };
        // The same file for the same method is the same submission.
        assert_eq!(
            store.create_submission(&new, None).await.unwrap(),
            Created::Duplicate(id)
        );
        let row = store.submission(id).await.unwrap().expect("stored");
        assert_eq!(row.status, Status::Queued);
        assert_eq!(row.protocols, protocols);
        assert_eq!(row.visibility, Visibility::Public);
        assert_eq!(row.preflight, f.preflight);
        assert_eq!(row.method, "CosyPose");
        assert_eq!(row.hardware, "a GPU");
        let method = store.method(row.method_id).await.unwrap().expect("method");
        assert_eq!(method.modality, Some(Modality::RgbD));
        assert_eq!(method.training_data, None);
        assert_eq!(
            store.queue_place(Some(id)).await.unwrap(),
            QueuePlace {
                queued_ahead: 0,
                running: 0
            }
        );
        // Stored without a counted work, a job counts its estimates.
        assert_eq!(store.work_ahead(None).await.unwrap(), 35);
        assert_eq!(store.measured_speed().await.unwrap(), None);

        // The queue: claim, heartbeat, finish only while the job is the worker's own.
        assert_eq!(ds.content_hash.as_deref(), Some("c0ffee"));
        let file = store.submission_file("aaaa").await.unwrap().expect("file");
        assert_eq!((file.size, file.gzip), (1234, vec![31, 139, 8]));
        assert!(store.files_missing().await.unwrap().is_empty());
        let job = store
            .claim("w1", 60_000, 3, &[])
            .await
            .unwrap()
            .expect("a job");
        assert_eq!((job.id, job.status, job.attempts), (id, Status::Running, 1));
        assert!(store.claim("w2", 60_000, 3, &[]).await.unwrap().is_none());
        // Released by its worker, the job is queued again with no attempt spent; a worker
        // that skips its dataset leaves it alone.
        assert!(!store.release(id, "w2").await.unwrap());
        assert!(store.release(id, "w1").await.unwrap());
        let back = store.submission(id).await.unwrap().unwrap();
        assert_eq!(
            (back.status, back.attempts, back.started_at),
            (Status::Queued, 0, None)
        );
        assert!(
            store
                .claim("w2", 60_000, 3, &[ds.id])
                .await
                .unwrap()
                .is_none()
        );
        // Queued again after a service failure, the attempt stays counted.
        let job = store
            .claim("w1", 60_000, 3, &[])
            .await
            .unwrap()
            .expect("a job");
        assert!(store.requeue(id, "w1", "disk full").await.unwrap());
        let job2 = store
            .claim("w1", 60_000, 3, &[])
            .await
            .unwrap()
            .expect("a job");
        assert_eq!((job.attempts, job2.attempts), (1, 2));
        assert!(store.release(id, "w1").await.unwrap());
        let job = store
            .claim("w1", 60_000, 3, &[])
            .await
            .unwrap()
            .expect("a job");
        assert_eq!((job.id, job.status, job.attempts), (id, Status::Running, 2));
        assert!(store.heartbeat(id, "w1", 60_000, 0.5, 7).await.unwrap());
        assert!(!store.heartbeat(id, "w2", 60_000, 0.5, 9).await.unwrap());
        assert_eq!(store.submission(id).await.unwrap().unwrap().work_done, 7);
        assert!(!store.finish(id, "w2", &done_job).await.unwrap());
        assert!(store.finish(id, "w1", &done_job).await.unwrap());
        // Finishing again (its first answer lost with the connection) is no second score set.
        assert!(store.finish(id, "w1", &done_job).await.unwrap());
        let done = store.submission(id).await.unwrap().unwrap();
        assert_eq!((done.status, done.progress), (Status::Done, 1.0));
        // The work the evaluator did and its time: the speed waits are estimated from.
        let work: i64 = reports.iter().map(|r| r.estimates_evaluated as i64).sum();
        assert_eq!(
            (done.work, done.work_done, done.eval_ms),
            (work, work, Some(1000))
        );
        assert_eq!(store.measured_speed().await.unwrap(), Some(work as f64));
        // The per-estimate errors come back typed, one set per protocol.
        let stored = store
            .estimate_errors(id, ProtocolName::Bop19)
            .await
            .unwrap()
            .expect("stored with the scores");
        assert_eq!(stored.rows_count as usize, error_rows.len());
        let rows = stored.rows().unwrap();
        assert_eq!(
            serde_json::to_value(&rows).unwrap(),
            serde_json::Value::Array(error_rows.clone())
        );
        assert!(
            store
                .estimate_errors(id, ProtocolName::Eccv18)
                .await
                .unwrap()
                .is_some()
        );
        assert!(!store.fail(id, "w1", "late", Fault::Service).await.unwrap());

        // Reports come back as they were stored, one per protocol.
        let mut stored = store.reports_of_submission(id).await.unwrap();
        stored.sort_by_key(|r| r.protocol);
        let mut expected = reports.to_vec();
        expected.sort_by_key(|r| r.protocol);
        assert_eq!(stored, expected);

        // The leaderboard entry, with its per-object scores, in one read.
        let board = store.leaderboard(ProtocolName::Bop19, None).await.unwrap();
        assert_eq!(board.len(), 1);
        assert_eq!(board[0].score.score, reports[0].headline());
        assert_eq!(board[0].head.modality, Some(Modality::RgbD));
        let objects: Vec<(i64, f64)> = reports[0]
            .obj_average_recalls
            .iter()
            .map(|(&o, &v)| (i64::from(o), v))
            .collect();
        assert_eq!(
            board[0]
                .object_scores
                .clone()
                .into_iter()
                .collect::<Vec<_>>(),
            objects
        );
        assert!(
            store
                .leaderboard(ProtocolName::Bop19, Some(DatasetId::new(ds.id.get() + 1)))
                .await
                .unwrap()
                .is_empty()
        );

        // The recent list names the owner and the headline scores; an anonymous method says
        // so on the rows every board reads, and in the list, until it is revealed.
        let recent = store.recent_public_finished(10, 0).await.unwrap();
        assert_eq!(recent.len(), 1);
        assert_eq!(recent[0].submission.id, id);
        assert_eq!(recent[0].bop19, Some(reports[0].headline()));
        assert_eq!((recent[0].ap, recent[0].map), (None, None));
        assert_eq!(recent[0].owner, "alice");
        assert!(!recent[0].anonymous && !board[0].head.anonymous);
        assert!(
            store
                .recent_public_finished(10, 1)
                .await
                .unwrap()
                .is_empty()
        );
        let method_id = board[0].head.method_id;
        assert!(store.set_method_anonymous(method_id, true).await.unwrap());
        assert!(store.method(method_id).await.unwrap().unwrap().anonymous);
        assert!(store.recent_public_finished(10, 0).await.unwrap()[0].anonymous);
        let board_now = store.leaderboard(ProtocolName::Bop19, None).await.unwrap();
        assert!(board_now[0].head.anonymous);
        assert!(store.set_method_anonymous(method_id, false).await.unwrap());
        assert!(!store.method(method_id).await.unwrap().unwrap().anonymous);

        // Hidden: off the boards; re-run: queued again; delete: gone, file unused.
        assert!(store.set_hidden(id, true).await.unwrap());
        assert!(
            store
                .leaderboard(ProtocolName::Eccv18, None)
                .await
                .unwrap()
                .is_empty()
        );
        assert!(
            store
                .recent_public_finished(10, 0)
                .await
                .unwrap()
                .is_empty()
        );
        assert!(store.rerun(id).await.unwrap());
        assert!(!store.rerun(id).await.unwrap());
        assert_eq!(
            store.submission(id).await.unwrap().unwrap().status,
            Status::Queued
        );
        let deleted = store.delete_submission(id).await.unwrap().expect("deleted");
        assert_eq!(
            (deleted.file_sha256.as_str(), deleted.file_unused),
            ("aaaa", true)
        );
        assert!(store.delete_submission(id).await.unwrap().is_none());
        assert!(store.submission_file("aaaa").await.unwrap().is_none());
    });
}
both_databases!(submissions_queue_and_scores);

/// A bop24 report of the BOP'24 fixture's `case` file on the reference dataset.
fn bop24_report(case: &str) -> evaluator::detection::DetectionReport {
    let targets = fixtures().join("../bop24/test_targets_bop24.json");
    let opts = evaluator::dataset::DatasetOptions {
        targets_file: targets.display().to_string(),
        ..Default::default()
    };
    let dataset = Dataset::load_with(&fixtures().join("dataset"), &opts).expect("dataset");
    let file = fixtures().join(format!("../bop24/results/{case}_synthA-test.csv"));
    let results = load_results(&file).expect("results");
    evaluator::detection::evaluate(
        &dataset,
        &results,
        100,
        &NoProgress,
        &AtomicBool::new(false),
    )
    .expect("evaluates")
}

/// bop24 submissions: the task is kept and tells the same file apart from a bop19 one; the
/// report stored when the job is done reads back typed and equal; the board ranks by
/// bop24_mAP, and a report that counted nothing (its mAPs NaN, stored as NULL) reads back and
/// ranks last on both databases.
fn bop24_scores(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let db = TestDb::new(kind, "store_bop24");
    let (exact, mut noisy) = (bop24_report("gtexact"), bop24_report("noisy"));
    // The noisy file's interval and replicates, as the worker stores a drawn bootstrap.
    let drawn = [0.25, 0.5, 0.75];
    noisy.bootstrap = Some(evaluator::bootstrap::BootstrapSummary {
        seed: 1,
        replicates: drawn.len(),
        ci95: [0.26, 0.74],
    });
    let mut nothing = noisy.clone();
    nothing.bootstrap = None;
    for v in [
        &mut nothing.bop24_map,
        &mut nothing.bop24_map_mssd,
        &mut nothing.bop24_map_mssd_mm,
        &mut nothing.bop24_map_mspd,
        &mut nothing.bop25_map,
        &mut nothing.bop25_map_mm,
    ] {
        *v = f64::NAN;
    }
    run(async {
        let (store, _) = store(kind, &db, dir.path()).await;
        let ds = store
            .register_dataset(&dataset_row("synthA"))
            .await
            .unwrap();
        let owner = user(&store, "alice").await;
        let mut ids = Vec::new();
        for (method, report) in [("exact", &exact), ("noisy", &noisy), ("nothing", &nothing)] {
            let f = fixture(method);
            let new = NewSubmission {
                task: Some(Task::Bop24),
                ..new_submission(&f, owner, ds.id, "bbbb", &[])
            };
            let Created::New(id) = store.create_submission(&new, None).await.unwrap() else {
                panic!("a new submission");
            };
            let row = store.submission(id).await.unwrap().expect("stored");
            assert_eq!((row.task, row.protocols.len()), (Some(Task::Bop24), 0));
            let job = store
                .claim("w1", 60_000, 3, &[])
                .await
                .unwrap()
                .expect("a job");
            assert_eq!(job.id, id);
            let replicates: &[f64] = if report.bootstrap.is_some() {
                &drawn
            } else {
                &[]
            };
            assert!(
                !store
                    .finish_bop24(id, "w2", report, replicates, 10)
                    .await
                    .unwrap()
            );
            assert!(
                store
                    .finish_bop24(id, "w1", report, replicates, 10)
                    .await
                    .unwrap()
            );
            // Finishing again (its first answer lost) is no second row.
            assert!(
                store
                    .finish_bop24(id, "w1", report, replicates, 10)
                    .await
                    .unwrap()
            );
            let done = store.submission(id).await.unwrap().unwrap();
            assert_eq!(done.status, Status::Done);
            assert_eq!(done.work, report.estimates_evaluated as i64);
            ids.push(id);
        }
        // The same file for the same method under bop19 is another submission.
        let f = fixture("exact");
        let as_bop19 = new_submission(&f, owner, ds.id, "bbbb", &[ProtocolName::Bop19]);
        assert!(matches!(
            store.create_submission(&as_bop19, None).await.unwrap(),
            Created::New(other) if other != ids[0]
        ));
        assert_eq!(
            store.bop24_report(ids[0]).await.unwrap(),
            Some(exact.clone())
        );
        assert_eq!(
            store.bop24_report(ids[1]).await.unwrap(),
            Some(noisy.clone())
        );
        let stored = store.bop24_report(ids[2]).await.unwrap().expect("stored");
        assert!(stored.bop24_map.is_nan() && stored.bop25_map_mm.is_nan());
        assert_eq!(stored.errors, nothing.errors);

        let board = store.bop24_leaderboard(None).await.unwrap();
        let order: Vec<SubmissionId> = board.iter().map(|e| e.head.submission_id).collect();
        assert_eq!(
            order, ids,
            "exact, noisy, then the one that counted nothing"
        );
        assert!(exact.bop24_map > noisy.bop24_map);
        // The interval and the replicates an average's interval is made of.
        assert_eq!(board[1].ci95, Some([0.26, 0.74]));
        assert_eq!((board[0].ci95, board[2].ci95), (None, None));
        let ids_of_scores: Vec<i64> = board.iter().map(|e| e.score_id).collect();
        let stored = store
            .replicates(&ids_of_scores, BoardProtocol::Bop24)
            .await
            .unwrap();
        assert_eq!(stored.len(), 1);
        assert_eq!(stored[&board[1].score_id], drawn);
        assert_eq!(board[1].report, noisy);
        assert_eq!(
            board[0].time_avg,
            Some(exact.bop24_average_time_per_image).filter(|t| *t >= 0.0)
        );
        assert_eq!(
            store
                .bop24_entry(board[1].head.method_id, ds.id)
                .await
                .unwrap(),
            Some((ids[1], false))
        );
        let mut mine = store.bop24_maps(Whose::Owner(owner)).await.unwrap();
        mine.sort_by_key(|m| m.0);
        assert_eq!(
            mine,
            [(ids[0], exact.bop24_map), (ids[1], noisy.bop24_map)],
            "a score only where one was counted"
        );
    });
}

both_databases!(bop24_scores);

fn fair_use_is_exact_under_concurrency(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let db = TestDb::new(kind, "store_fair_use");
    run(async {
        let (store, _) = store(kind, &db, dir.path()).await;
        let ds = store
            .register_dataset(&dataset_row("synthA"))
            .await
            .unwrap();
        let owner = user(&store, "bob").await;
        // Twelve parallel uploads of different files for a method that does not exist yet,
        // against a limit of 5: exactly five are created, the others are refused, none fails.
        let tasks: Vec<_> = (0..12)
            .map(|i| {
                let store = store.clone();
                tokio::spawn(async move {
                    let f = fixture("NewMethod");
                    let sha = format!("sha{i}");
                    let protocols = [ProtocolName::Bop19];
                    let new = new_submission(&f, owner, ds.id, &sha, &protocols);
                    let limit = FairUse { limit: 5, since: 0 };
                    store.create_submission(&new, Some(limit)).await
                })
            })
            .collect();
        let mut created = 0;
        let mut limited = 0;
        for t in tasks {
            match t.await.unwrap().expect("no store error") {
                Created::New(_) => created += 1,
                Created::Limited { times } => {
                    assert_eq!(times.len(), 5);
                    limited += 1;
                }
                Created::Duplicate(_) => panic!("different files are not duplicates"),
            }
        }
        assert_eq!((created, limited), (5, 7));
        // The times the limit counted are the ones a user is shown: five, oldest first; none
        // on another dataset, by another owner, or before `since`.
        let times = store.counted_times(owner, ds.id, 0).await.unwrap();
        assert_eq!(times.len(), 5);
        assert!(times.windows(2).all(|w| w[0] <= w[1]), "{times:?}");
        let later = times[4] + 1;
        assert!(
            store
                .counted_times(owner, ds.id, later)
                .await
                .unwrap()
                .is_empty()
        );
        let other_ds = store
            .register_dataset(&dataset_row("synthB"))
            .await
            .unwrap();
        assert!(
            store
                .counted_times(owner, other_ds.id, 0)
                .await
                .unwrap()
                .is_empty()
        );
        let stranger = user(&store, "dave").await;
        assert!(
            store
                .counted_times(stranger, ds.id, 0)
                .await
                .unwrap()
                .is_empty()
        );
        // A refused upload of a new method leaves no method behind.
        let other = user(&store, "carol").await;
        let f = fixture("NeverCreated");
        let protocols = [ProtocolName::Bop19];
        let new = new_submission(&f, other, ds.id, "x", &protocols);
        let refused = store
            .create_submission(&new, Some(FairUse { limit: 0, since: 0 }))
            .await
            .unwrap();
        assert_eq!(refused, Created::Limited { times: Vec::new() });
        assert!(
            store
                .public_methods()
                .await
                .unwrap()
                .iter()
                .all(|m| m.name != "NeverCreated")
        );
    });
}
both_databases!(fair_use_is_exact_under_concurrency);

fn accounts_and_audit(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let db = TestDb::new(kind, "store_accounts");
    run(async {
        let (store, _) = store(kind, &db, dir.path()).await;
        let id = user(&store, "dora").await;
        let taken = store
            .create_user(&UserName::parse("dora").unwrap(), "h", true)
            .await;
        assert!(matches!(taken, Err(StoreError::Unique { .. })), "{taken:?}");
        let (u, hash) = store.user_for_login("dora").await.unwrap().expect("found");
        assert_eq!(
            (u.id, u.is_admin, hash.as_str()),
            (id, false, "$argon2id$not-a-real-hash")
        );

        store
            .create_session(id, "s-hash", "csrf", 60_000)
            .await
            .unwrap();
        let s = store
            .session("s-hash")
            .await
            .unwrap()
            .expect("live session");
        assert_eq!((s.user.id, s.csrf_token.as_str()), (id, "csrf"));
        store.create_session(id, "old", "c", -1).await.unwrap();
        assert!(store.session("old").await.unwrap().is_none(), "expired");
        store.delete_session("s-hash").await.unwrap();
        assert!(store.session("s-hash").await.unwrap().is_none());

        let label = TokenLabel::parse("ci").unwrap();
        let tid = store.create_token(id, &label, "t-hash").await.unwrap();
        assert_eq!(
            store.user_for_token("t-hash").await.unwrap().map(|u| u.id),
            Some(id)
        );
        assert!(store.tokens(id).await.unwrap()[0].last_used_at.is_some());
        assert!(store.revoke_token(id, tid).await.unwrap());
        assert!(!store.revoke_token(id, tid).await.unwrap());
        assert!(store.user_for_token("t-hash").await.unwrap().is_none());
        let dup = store.create_token(id, &label, "t-hash").await;
        assert!(matches!(dup, Err(StoreError::Unique { .. })), "{dup:?}");

        // Counters move only from the value last seen: of two writers, one wins.
        // (Times in the future: counters idle for a day are cleared as new ones come.)
        let first = Counter {
            attempts: 1,
            since: 4_000_000_000_000,
            next_at: 4_000_000_000_000,
        };
        let second = Counter {
            attempts: 2,
            ..first
        };
        assert!(store.swap_counter("k", None, &first).await.unwrap());
        assert!(!store.swap_counter("k", None, &first).await.unwrap());
        assert!(
            store
                .swap_counter("k", Some(&first), &second)
                .await
                .unwrap()
        );
        assert!(
            !store
                .swap_counter("k", Some(&first), &second)
                .await
                .unwrap()
        );
        assert_eq!(store.counter("k").await.unwrap(), Some(second));
        store.delete_counter("k").await.unwrap();
        assert_eq!(store.counter("k").await.unwrap(), None);
        assert!(!store.signed_in_from("dora", "127.0.0.1").await.unwrap());
        store.remember_sign_in("dora", "127.0.0.1").await.unwrap();
        store.remember_sign_in("dora", "127.0.0.1").await.unwrap();
        assert!(store.signed_in_from("dora", "127.0.0.1").await.unwrap());
        assert!(!store.signed_in_from("dora", "127.0.0.2").await.unwrap());

        store
            .audit(id, AdminAction::Hide, "submission 1")
            .await
            .unwrap();
        store
            .audit(id, AdminAction::AddDataset, "lmo")
            .await
            .unwrap();
        let log = store.audit_log(10).await.unwrap();
        let actions: Vec<AdminAction> = log.iter().map(|e| e.action).collect();
        assert_eq!(actions, [AdminAction::AddDataset, AdminAction::Hide]);
        assert_eq!(log[0].actor, "dora");
    });
}
both_databases!(accounts_and_audit);

fn unknown_stored_values_are_errors(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let db = TestDb::new(kind, "store_corrupt");
    run(async {
        let (store, url) = store(kind, &db, dir.path()).await;
        let ds = store
            .register_dataset(&dataset_row("synthA"))
            .await
            .unwrap();
        let owner = user(&store, "eve").await;
        let f = fixture("M");
        let protocols = [ProtocolName::Bop19];
        let Created::New(id) = store
            .create_submission(&new_submission(&f, owner, ds.id, "s", &protocols), None)
            .await
            .unwrap()
        else {
            panic!("created");
        };
        raw(
            &url,
            &format!("UPDATE submissions SET status = 'paused' WHERE id = {id}"),
        )
        .await;
        match store.submission(id).await {
            Err(StoreError::Corrupt { column, value }) => {
                assert_eq!((column, value.as_str()), ("status", "paused"))
            }
            other => panic!("expected a corrupt status, got {other:?}"),
        }
        raw(
            &url,
            &format!(
                "UPDATE submissions SET status = 'queued', protocols = 'bop99' WHERE id = {id}"
            ),
        )
        .await;
        assert!(matches!(
            store.submission(id).await,
            Err(StoreError::Corrupt {
                column: "protocols",
                ..
            })
        ));
        raw(
            &url,
            &format!("UPDATE submissions SET protocols = 'bop19' WHERE id = {id}"),
        )
        .await;
        raw(
            &url,
            &format!("UPDATE methods SET modality = 'thermal' WHERE owner_id = {owner}"),
        )
        .await;
        assert!(matches!(
            store.public_methods().await,
            Err(StoreError::Corrupt {
                column: "modality",
                ..
            })
        ));
        raw(&url, "INSERT INTO audit_log (actor_id, action, target, at) SELECT id, 'promote', 'x', 0 FROM users").await;
        assert!(matches!(
            store.audit_log(5).await,
            Err(StoreError::Corrupt {
                column: "action",
                ..
            })
        ));
    });
}
both_databases!(unknown_stored_values_are_errors);

/// The board version moves, in the database and in this store's own count, with every change a
/// leaderboard can show, and with nothing else: servers sharing the database rely on it to drop
/// their rendered boards.
fn board_version_follows_board_changes(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let db = TestDb::new(kind, "store_board_version");
    let (done_job, _) = finished(&[ProtocolName::Bop19]);
    run(async {
        let (store, url) = store(kind, &db, dir.path()).await;
        // Another process's store on the same database sees every change, counted or not.
        let other = Store::connect(&url).await.unwrap();
        let mut last = (store.board_version().await.unwrap(), 0);
        let mut check = |changed: bool, what: &str, now: (i64, u64), seen: i64| {
            assert_eq!(now.0 > last.0, changed, "{kind:?}: {what} (database)");
            assert_eq!(now.1 > last.1, changed, "{kind:?}: {what} (this store)");
            assert_eq!(
                seen, now.0,
                "{what}: the other store reads the same version"
            );
            last = now;
        };
        macro_rules! step {
            ($changed:expr, $what:expr, $call:expr) => {{
                let out = $call;
                let now = (
                    store.board_version().await.unwrap(),
                    store.local_board_changes(),
                );
                check($changed, $what, now, other.board_version().await.unwrap());
                out
            }};
        }
        let ds = step!(
            true,
            "dataset registered",
            store
                .register_dataset(&dataset_row("synthA"))
                .await
                .unwrap()
        );
        let owner = user(&store, "alice").await;
        let f = fixture("CosyPose");
        let protocols = [ProtocolName::Bop19];
        let Created::New(id) = step!(
            false,
            "new method's submission queued",
            store
                .create_submission(&new_submission(&f, owner, ds.id, "aaaa", &protocols), None)
                .await
                .unwrap()
        ) else {
            panic!("new");
        };
        step!(
            false,
            "claimed",
            store.claim("w1", 60_000, 3, &[]).await.unwrap()
        );
        step!(
            false,
            "heartbeat",
            store.heartbeat(id, "w1", 60_000, 0.5, 1).await.unwrap()
        );
        assert!(step!(
            false,
            "another worker's finish",
            !store.finish(id, "w2", &done_job).await.unwrap()
        ));
        assert!(step!(
            true,
            "finished",
            store.finish(id, "w1", &done_job).await.unwrap()
        ));
        assert!(step!(
            true,
            "withdrawn",
            store.set_visibility(id, Visibility::Private).await.unwrap()
        ));
        assert!(step!(
            false,
            "held while private",
            store.hold_publication(id).await.unwrap()
        ));
        assert!(store.submission(id).await.unwrap().unwrap().held);
        assert!(step!(
            true,
            "published",
            store.set_visibility(id, Visibility::Public).await.unwrap()
        ));
        assert!(!store.submission(id).await.unwrap().unwrap().held);
        assert!(step!(
            true,
            "hidden",
            store.set_hidden(id, true).await.unwrap()
        ));
        assert!(step!(
            false,
            "nothing hidden",
            !store
                .set_hidden(SubmissionId::new(id.get() + 99), true)
                .await
                .unwrap()
        ));
        assert!(step!(
            true,
            "shown",
            store.set_hidden(id, false).await.unwrap()
        ));
        assert!(step!(
            true,
            "pinned",
            store.set_pinned(id, true).await.unwrap()
        ));
        assert!(step!(
            true,
            "unpinned",
            store.set_pinned(id, false).await.unwrap()
        ));
        assert!(step!(
            false,
            "nothing to unpin",
            !store.set_pinned(id, false).await.unwrap()
        ));
        let method_id = store.submission(id).await.unwrap().expect("row").method_id;
        assert!(step!(
            true,
            "method details",
            store
                .set_method_details(method_id, &MethodDetails::default())
                .await
                .unwrap()
        ));
        assert!(step!(
            true,
            "core dataset",
            store.set_dataset_core("synthA", false).await.unwrap()
        ));
        assert!(step!(
            false,
            "no such dataset",
            !store.set_dataset_core("nothing", true).await.unwrap()
        ));
        // The same method's next upload changes its metadata, which the boards show.
        let mut g = fixture("CosyPose");
        g.meta.modality = Some(Modality::Rgb);
        step!(
            true,
            "method metadata",
            store
                .create_submission(&new_submission(&g, owner, ds.id, "bbbb", &protocols), None)
                .await
                .unwrap()
        );
        assert!(step!(true, "re-run", store.rerun(id).await.unwrap()));
        let job = step!(
            false,
            "claimed",
            store.claim("w1", 60_000, 3, &[]).await.unwrap()
        );
        assert!(step!(
            false,
            "failed",
            store
                .fail(job.expect("a job").id, "w1", "bad", Fault::User)
                .await
                .unwrap()
        ));
        assert!(step!(
            true,
            "deleted",
            store.delete_submission(id).await.unwrap().is_some()
        ));
        assert!(step!(
            false,
            "nothing deleted",
            store.delete_submission(id).await.unwrap().is_none()
        ));
        assert!(step!(
            true,
            "retired",
            store.retire_dataset("synthA").await.unwrap()
        ));
        assert!(step!(
            false,
            "already retired",
            !store.retire_dataset("synthA").await.unwrap()
        ));
        assert!(step!(
            true,
            "revived",
            store.revive_dataset("synthA").await.unwrap()
        ));
    });
}
both_databases!(board_version_follows_board_changes);

/// Teams: a unique name, the creator as first member, invitations used up by accepting, and
/// methods of the team's own that every member's upload reaches (each submission staying its
/// uploader's), apart from the members' personal methods of the same name.
fn teams_and_their_methods(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "store_teams");
    run(async {
        let (store, _) = store(kind, &db, dir.path()).await;
        let ds = store
            .register_dataset(&dataset_row("synthA"))
            .await
            .unwrap();
        let (alice, bob) = (user(&store, "alice").await, user(&store, "bob").await);
        let name = TeamName::parse("team", "lab").unwrap();
        let team = store.create_team(&name, alice).await.unwrap();
        assert!(matches!(
            store.create_team(&name, bob).await,
            Err(StoreError::Unique { .. })
        ));
        assert!(store.is_member(team, alice).await.unwrap());
        assert!(!store.is_member(team, bob).await.unwrap());
        // Accepting without an invitation changes nothing; with one, it is used up.
        assert!(!store.accept_invitation(team, bob).await.unwrap());
        store.invite(team, bob, alice).await.unwrap();
        store.invite(team, bob, alice).await.unwrap();
        let waiting = store.invitations_of(bob).await.unwrap();
        assert_eq!(waiting.len(), 1);
        assert_eq!(
            (waiting[0].team.as_str(), waiting[0].invited_by.as_str()),
            ("lab", "alice")
        );
        assert!(store.accept_invitation(team, bob).await.unwrap());
        assert!(store.invitations_of(bob).await.unwrap().is_empty());
        assert!(store.is_member(team, bob).await.unwrap());
        let members: Vec<String> = store
            .members(team)
            .await
            .unwrap()
            .into_iter()
            .map(|m| m.name)
            .collect();
        assert_eq!(members, ["alice", "bob"]);
        assert_eq!(store.teams_of(bob).await.unwrap()[0].name, "lab");
        let found = store.team_by_name("lab").await.unwrap().expect("the team");
        assert_eq!(
            (found.id, found.creator_id, found.creator.as_str()),
            (team, alice, "alice")
        );

        // Both members' uploads reach the team's one method; Alice's personal method of the
        // same name is another.
        let f = fixture("joint");
        let protocols = [ProtocolName::Bop19];
        let to_team = |owner, sha| NewSubmission {
            team_id: Some(team),
            visibility: Visibility::Private,
            ..new_submission(&f, owner, ds.id, sha, &protocols)
        };
        let Created::New(a) = store
            .create_submission(&to_team(alice, "a1"), None)
            .await
            .unwrap()
        else {
            panic!("new");
        };
        let Created::New(b) = store
            .create_submission(&to_team(bob, "b1"), None)
            .await
            .unwrap()
        else {
            panic!("new");
        };
        let own = new_submission(&f, alice, ds.id, "a2", &protocols);
        let Created::New(c) = store.create_submission(&own, None).await.unwrap() else {
            panic!("new");
        };
        let (a, b, c) = (
            store.submission(a).await.unwrap().unwrap(),
            store.submission(b).await.unwrap().unwrap(),
            store.submission(c).await.unwrap().unwrap(),
        );
        assert_eq!(a.method_id, b.method_id);
        assert_ne!(a.method_id, c.method_id);
        assert_eq!((a.owner_id, b.owner_id), (Some(alice), Some(bob)));
        assert_eq!((a.team_id, c.team_id), (Some(team), None));
        let method = store.method(a.method_id).await.unwrap().expect("method");
        assert_eq!(
            (method.owner.as_str(), method.team.as_deref()),
            ("lab", Some("lab"))
        );
        assert_eq!((method.owner_id, method.team_id), (None, Some(team)));
        let personal = store.method(c.method_id).await.unwrap().expect("method");
        assert_eq!((personal.owner.as_str(), personal.team), ("alice", None));
        // Only members' eyes see a method without a public submission.
        assert_eq!(store.team_methods(team, true).await.unwrap().len(), 0);
        assert_eq!(
            store.team_methods(team, false).await.unwrap()[0].id,
            method.id
        );
        // The same file again by the other member is the same submission.
        let again = store
            .create_submission(&to_team(alice, "b1"), None)
            .await
            .unwrap();
        assert_eq!(again, Created::Duplicate(b.id));

        assert!(store.remove_member(team, bob).await.unwrap());
        assert!(!store.remove_member(team, bob).await.unwrap());
        assert!(!store.is_member(team, bob).await.unwrap());
    });
}
both_databases!(teams_and_their_methods);

/// Groups of datasets: BOP's three seeded by the migration; a group is saved, its members
/// replaced, deleted with them; every change moves the board version.
fn dataset_groups(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "store_groups");
    run(async {
        let (store, _) = store(kind, &db, dir.path()).await;
        let names = |groups: &[server::store::groups::GroupRow]| {
            groups.iter().map(|g| g.name.clone()).collect::<Vec<_>>()
        };
        let seeded = store.groups().await.expect("groups");
        assert_eq!(
            names(&seeded),
            ["BOP-Classic-Core", "BOP-Industrial", "BOP-H3"],
            "{kind:?}"
        );
        assert_eq!(seeded[2].datasets, ["handal", "hopev2", "hot3d"]);

        let name = GroupName::parse("mine").expect("name");
        let members = |list: &[&str]| {
            list.iter()
                .map(|d| DatasetName::parse(d).expect("dataset"))
                .collect::<Vec<_>>()
        };
        let version = store.board_version().await.expect("version");
        assert!(
            store
                .save_group(&name, &members(&["lmo", "synthA"]))
                .await
                .expect("saved")
        );
        assert!(store.board_version().await.expect("version") > version);
        // Saved again: the members are replaced, the group is not new.
        assert!(
            !store
                .save_group(&name, &members(&["ycbv"]))
                .await
                .expect("saved")
        );
        let groups = store.groups().await.expect("groups");
        assert_eq!(names(&groups).last().map(String::as_str), Some("mine"));
        assert_eq!(groups.last().expect("mine").datasets, ["ycbv"]);
        assert!(store.delete_group(&name).await.expect("deleted"));
        assert!(!store.delete_group(&name).await.expect("answered"));
        assert_eq!(
            names(&store.groups().await.expect("groups")),
            names(&seeded)
        );
        // A deleted group leaves no member behind for a new group of the same name.
        assert!(store.save_group(&name, &[]).await.expect("saved"));
        assert!(
            store
                .groups()
                .await
                .expect("groups")
                .last()
                .expect("mine")
                .datasets
                .is_empty()
        );
    });
}
both_databases!(dataset_groups);

/// Each host's preparation of a dataset is one row per host and folder, written over as it
/// goes, and listed by dataset; a state the service does not know is corruption.
fn dataset_preparations(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let db = TestDb::new(kind, "store_preparations");
    run(async {
        let (store, url) = store(kind, &db, dir.path()).await;
        let a = store
            .register_dataset(&dataset_row("synthA"))
            .await
            .unwrap();
        let b = store
            .register_dataset(&dataset_row("synthB"))
            .await
            .unwrap();
        assert!(store.preparations().await.unwrap().is_empty());
        let row = |dataset_id, host: &str, state, done, detail: Option<&str>| PreparationRow {
            dataset_id,
            host: host.to_string(),
            folder: "/data/prepared".to_string(),
            state,
            images_done: done,
            images_total: 8,
            detail: detail.map(str::to_string),
            updated_at: 0,
        };
        let waiting = Some("waiting for another process");
        for saved in [
            row(b.id, "m1", PreparationState::Preparing, 0, waiting),
            row(a.id, "m2", PreparationState::Failed, 0, Some("no copy")),
            row(a.id, "m1", PreparationState::Preparing, 3, None),
            row(a.id, "m1", PreparationState::Ready, 8, None),
        ] {
            store.save_preparation(&saved).await.unwrap();
        }
        let listed = store.preparations().await.unwrap();
        let key = |p: &PreparationRow| (p.dataset_id, p.host.clone(), p.state, p.images_done);
        assert_eq!(
            listed.iter().map(key).collect::<Vec<_>>(),
            [
                (a.id, "m1".to_string(), PreparationState::Ready, 8),
                (a.id, "m2".to_string(), PreparationState::Failed, 0),
                (b.id, "m1".to_string(), PreparationState::Preparing, 0),
            ]
        );
        assert_eq!(listed[0].detail, None);
        assert_eq!(listed[1].detail.as_deref(), Some("no copy"));
        assert_eq!(listed[2].detail.as_deref(), waiting);
        assert!(
            listed
                .iter()
                .all(|p| p.updated_at > 0 && p.images_total == 8)
        );

        raw(
            &url,
            "UPDATE dataset_preparations SET state = 'paused' WHERE host = 'm2'",
        )
        .await;
        match store.preparations().await {
            Err(StoreError::Corrupt { column, value }) => {
                assert_eq!((column, value.as_str()), ("state", "paused"))
            }
            other => panic!("expected a corrupt state, got {other:?}"),
        }
    });
}
both_databases!(dataset_preparations);
