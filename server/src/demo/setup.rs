//! The first-start experience: with nothing configured, the service generates a small
//! synthetic dataset and a few demo submissions, so that a newcomer sees a live leaderboard.
//! The demo files go through the same submissions service as any upload.

use std::path::Path;

use crate::app::App;
use crate::datasets::config::BOP24_TARGETS;
use crate::demo::{
    DEMO_DATASET, SynthOptions, write_dataset, write_demo_coco_results,
    write_demo_detection_results, write_demo_results,
};
use crate::domain::{
    Description, Hardware, MethodName, Modality, Password, Task, TrainingData, UserName, Visibility,
};
use crate::service::accounts::{new_secret, register};
use crate::service::submissions::{Limit, Protocols, Upload, UploadedFile, submit_under};
use crate::store::methods::MethodMeta;

/// The account that owns the demo submissions.
pub const DEMO_USER: &str = "demo";

/// Writes the demo dataset into `datasets_dir` unless it holds datasets already.
pub async fn ensure_demo_dataset(datasets_dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(datasets_dir)?;
    let has_datasets = std::fs::read_dir(datasets_dir)?
        .filter_map(|e| e.ok())
        .any(|e| e.path().join("test_targets_bop19.json").is_file());
    if has_datasets {
        return Ok(());
    }
    let dir = datasets_dir.join(DEMO_DATASET);
    // A half-written folder from an interrupted start is replaced.
    if dir.exists() {
        std::fs::remove_dir_all(&dir)?;
    }
    tracing::info!(dir = %dir.display(), "generating the demo dataset");
    let target = dir.clone();
    tokio::task::spawn_blocking(move || write_dataset(&target, &SynthOptions::default())).await??;
    Ok(())
}

/// Submits the demo result files once, when the service has no submission yet.
pub async fn ensure_demo_submissions(app: &App) -> anyhow::Result<()> {
    if app.store.has_submissions().await? {
        return Ok(());
    }
    let Some(row) = app.store.dataset_by_name(DEMO_DATASET).await? else {
        return Ok(());
    };
    // The demo methods belong to an account nobody can sign in to (its password is random).
    let owner = match app.store.user_by_name(DEMO_USER).await? {
        Some(u) => u,
        None => {
            let name = UserName::parse(DEMO_USER)?;
            register(&app.store, &name, &Password::parse(&new_secret())?, false).await?;
            app.store
                .user_by_name(DEMO_USER)
                .await?
                .ok_or_else(|| anyhow::anyhow!("the demo account was not created"))?
        }
    };
    let out = tempfile::tempdir_in(&app.config.data_dir)?;
    let dataset_dir = std::path::PathBuf::from(&row.path);
    let out_dir = out.path().to_path_buf();
    let demos = tokio::task::spawn_blocking(move || -> anyhow::Result<_> {
        // The `.csv` files are scored under the 6D protocols, the `.json` files (BOP'22 2D
        // results) for the task read from them, and the detector's for bop24, when the dataset
        // has its targets (one generated before it had them has none).
        let mut demos: Vec<_> = write_demo_results(&dataset_dir, &out_dir, 11)?
            .into_iter()
            .chain(write_demo_coco_results(&dataset_dir, &out_dir, 11)?)
            .map(|d| (d, None))
            .collect();
        if dataset_dir.join(BOP24_TARGETS).is_file() {
            let detector = write_demo_detection_results(&dataset_dir, &out_dir, 11)?;
            demos.push((detector, Some(Task::Bop24)));
        }
        Ok(demos)
    })
    .await??;
    for (demo, task) in demos {
        let bytes = std::fs::read(&demo.path)?;
        let name = demo
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let upload = Upload {
            method: MethodName::parse(&demo.method)?,
            team: None,
            dataset: Some(row.name.clone()),
            protocols: Protocols::asked(&[]),
            task,
            meta: MethodMeta {
                description: Description::parse(&demo.description)?,
                training_data: Some(TrainingData::Synthetic),
                modality: Some(Modality::RgbD),
                ..MethodMeta::default()
            },
            hardware: Hardware::parse("demo data: times are made up")?,
            visibility: Some(Visibility::Public),
            files: vec![UploadedFile::from_bytes(
                &app.config.submissions_dir(),
                &name,
                &bytes,
            )?],
        };
        submit_under(app, &owner, upload, Limit::Exempt).await?;
        tracing::info!(method = %demo.method, "demo submission queued");
    }
    Ok(())
}
