//! The layering of both crates, read from their sources: no module reaches a module that
//! reaches it back (through `crate::` paths); in the server, web -> service -> store and
//! worker -> service/store, nothing outside `web/` names it (apart from where the app is
//! assembled) or mentions axum or askama, the store never names the service's error type, and
//! the web layer holds no SQL and never reaches the store (its handlers call services). A text
//! check, like a reviewer's: cheap, and it fails the build the day a circle comes back.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every `.rs` file under `src`, as (module path, source without its `#[cfg(test)]` part).
fn modules(src: &Path) -> BTreeMap<String, (PathBuf, String)> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("source folder") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            if path.extension().is_none_or(|e| e != "rs") {
                continue;
            }
            let rel = path
                .strip_prefix(src)
                .expect("under src")
                .with_extension("");
            let mut parts: Vec<String> = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if matches!(
                parts.last().map(String::as_str),
                Some("mod" | "lib" | "main")
            ) {
                parts.pop();
            }
            let text = std::fs::read_to_string(&path).expect("source");
            let text = match text.find("#[cfg(test)]") {
                Some(i) => text[..i].to_string(),
                None => text,
            };
            out.insert(parts.join("::"), (path, text));
        }
    }
    out
}

/// The `crate::a::b` paths of a source, as segment lists.
fn crate_paths(text: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("crate::") {
        let before = rest[..i].chars().last();
        rest = &rest[i + "crate::".len()..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '$') {
            continue;
        }
        let mut segs = Vec::new();
        let mut tail = rest;
        loop {
            let len = tail
                .find(|c: char| !(c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'))
                .unwrap_or(tail.len());
            if len == 0 {
                break;
            }
            segs.push(tail[..len].to_string());
            match tail[len..].strip_prefix("::") {
                Some(t) => tail = t,
                None => break,
            }
        }
        if !segs.is_empty() {
            out.push(segs);
        }
    }
    out
}

/// Module -> modules it names (the longest named prefix that is a module; not its parents or
/// children).
fn edges(mods: &BTreeMap<String, (PathBuf, String)>) -> BTreeMap<String, BTreeSet<String>> {
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (module, (_, text)) in mods {
        let entry = edges.entry(module.clone()).or_default();
        if module.is_empty() {
            continue;
        }
        for segs in crate_paths(text) {
            let target = (1..=segs.len())
                .rev()
                .map(|k| segs[..k].join("::"))
                .find(|cand| mods.contains_key(cand));
            if let Some(t) = target
                && t != *module
                && !module.starts_with(&format!("{t}::"))
                && !t.starts_with(&format!("{module}::"))
            {
                entry.insert(t);
            }
        }
    }
    edges
}

/// Groups of modules that reach each other (strongly connected components of two or more).
fn circles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    let reach = |from: &str| -> BTreeSet<String> {
        let mut seen = BTreeSet::new();
        let mut todo = vec![from.to_string()];
        while let Some(m) = todo.pop() {
            for next in edges.get(&m).into_iter().flatten() {
                if seen.insert(next.clone()) {
                    todo.push(next.clone());
                }
            }
        }
        seen
    };
    let reached: BTreeMap<&String, BTreeSet<String>> =
        edges.keys().map(|m| (m, reach(m))).collect();
    let mut out: Vec<Vec<String>> = Vec::new();
    for (m, from_m) in &reached {
        let group: Vec<String> = from_m
            .iter()
            .filter(|o| reached.get(o).is_some_and(|r| r.contains(*m)))
            .cloned()
            .collect();
        if group.len() > 1 && !out.contains(&group) {
            out.push(group);
        }
    }
    out
}

fn crate_src(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(name)
        .join("src")
}

#[test]
fn no_module_reaches_a_module_that_reaches_it_back() {
    for krate in ["evaluator", "server"] {
        let mods = modules(&crate_src(krate));
        assert!(mods.len() > 10, "{krate}: found its modules");
        let circles = circles(&edges(&mods));
        assert!(
            circles.is_empty(),
            "{krate}: modules in a circle: {circles:?}"
        );
    }
}

#[test]
fn the_checker_finds_a_circle() {
    let mut mods = BTreeMap::new();
    for (name, text) in [
        ("a", "use crate::b::Thing;"),
        ("b", "fn f() { crate::c::g() }"),
        ("c", "use crate::a;"),
        ("d", "use crate::a::x;"),
    ] {
        mods.insert(name.to_string(), (PathBuf::new(), text.to_string()));
    }
    assert_eq!(circles(&edges(&mods)), vec![vec!["a", "b", "c"]]);
}

/// The layer a module belongs to: the folder it sits in under `src` (`web`, `service`, `worker`,
/// `datasets`, `store`, `ops`, `cli`, `demo`), or `shared` for the files at the root (the app
/// state, configuration, domain values, the error type) that every layer may use.
fn layer(module: &str) -> &str {
    let top = module.split("::").next().unwrap_or("");
    match top {
        "web" | "service" | "worker" | "datasets" | "store" | "ops" | "cli" | "demo" => top,
        _ => "shared",
    }
}

/// The layers a layer must not name: web -> service -> store, worker -> service/store; the
/// shared root, datasets and ops sit under the services, and nothing but the web layer (and the
/// assembly of the app) reaches the web layer.
fn forbidden(layer: &str) -> &'static [&'static str] {
    match layer {
        "store" => &["web", "service", "worker", "datasets", "ops", "cli", "demo"],
        "service" => &["web", "worker", "cli", "demo"],
        "worker" => &["web", "cli", "demo"],
        "datasets" | "ops" | "shared" => &["web", "service", "worker", "cli", "demo"],
        "demo" => &["web", "worker", "cli"],
        _ => &[],
    }
}

/// Modules that assemble the app and so may name every layer.
const ASSEMBLY: [&str; 2] = ["", "cli::service"];

/// Whether a source reads or writes through the app's store (`app.store.x`, `&app.store`,
/// `app\n.store\n.x`): a field named `store` followed by anything but a call, so that an
/// atomic's `.store(v, ordering)` is not taken for it.
fn reaches_the_store(text: &str) -> bool {
    text.match_indices(".store").any(|(i, m)| {
        text[i + m.len()..]
            .chars()
            .next()
            .is_none_or(|c| !(c.is_alphanumeric() || c == '_' || c == '('))
    })
}

fn rule_breaks(mods: &BTreeMap<String, (PathBuf, String)>) -> Vec<String> {
    let sql = [
        "sqlx::query",
        "\"SELECT",
        "\"INSERT INTO",
        "\"DELETE FROM",
        "\"UPDATE ",
    ];
    let mut out = Vec::new();
    for (module, targets) in edges(mods) {
        if ASSEMBLY.contains(&module.as_str()) {
            continue;
        }
        let from = layer(&module);
        for target in targets {
            let to = layer(&target);
            if to != from && forbidden(from).contains(&to) {
                out.push(format!("{module} ({from}) names {target} ({to})"));
            }
        }
    }
    for (module, (_, text)) in mods {
        let from = layer(module);
        if from != "web" && (text.contains("axum") || text.contains("askama")) {
            out.push(format!(
                "{module} mentions axum or askama outside the web layer"
            ));
        }
        if from == "store" && (text.contains("crate::error") || text.contains("AppError")) {
            out.push(format!(
                "{module} (the store) names the service's error type"
            ));
        }
        if from == "web" {
            for s in sql {
                if text.contains(s) {
                    out.push(format!("{module} (the web layer) holds SQL: {s}"));
                }
            }
            if reaches_the_store(text) {
                out.push(format!(
                    "{module} (the web layer) reaches the store instead of a service"
                ));
            }
        }
    }
    out
}

#[test]
fn every_layer_names_only_the_layers_under_it() {
    let mods = modules(&crate_src("server"));
    for top in [
        "web", "service", "worker", "datasets", "store", "ops", "cli", "demo",
    ] {
        assert!(mods.contains_key(top), "server has its `{top}` folder");
    }
    let breaks = rule_breaks(&mods);
    assert!(breaks.is_empty(), "layering broken:\n{}", breaks.join("\n"));
}

#[test]
fn the_layer_checker_finds_each_kind_of_break() {
    let mut mods = BTreeMap::new();
    for (name, text) in [
        ("web", ""),
        ("web::views", "use crate::service::accounts;"),
        ("service", ""),
        (
            "service::accounts",
            "use crate::web::views::Page; use crate::store::Store;",
        ),
        ("store", "use crate::error::AppError;"),
        (
            "worker",
            "use crate::service::accounts; use crate::store::Store;",
        ),
        ("app", "use axum::Router;"),
        ("cli::service", "use crate::web::views;"),
        ("web::routes", "let d = app.store.datasets().await?;"),
        (
            "web::auth",
            "let u = app\n    .store\n    .user(id)\n    .await?;",
        ),
        ("web::cache", "fetch(&app.store, sha256)"),
        (
            "web::serve",
            "self.last.store(ms, Ordering::Relaxed); self.stored.x();",
        ),
    ] {
        mods.insert(name.to_string(), (PathBuf::new(), text.to_string()));
    }
    assert_eq!(
        rule_breaks(&mods),
        vec![
            "service::accounts (service) names web::views (web)".to_string(),
            "app mentions axum or askama outside the web layer".to_string(),
            "store (the store) names the service's error type".to_string(),
            "web::auth (the web layer) reaches the store instead of a service".to_string(),
            "web::cache (the web layer) reaches the store instead of a service".to_string(),
            "web::routes (the web layer) reaches the store instead of a service".to_string(),
        ]
    );
}

#[test]
fn the_root_of_server_src_stays_small() {
    // Files at the root besides the module files of its folders: at most 12.
    let src = crate_src("server");
    let mut loose = Vec::new();
    for entry in std::fs::read_dir(&src).expect("src") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "rs") && !path.with_extension("").is_dir() {
            loose.push(
                path.file_name()
                    .expect("name")
                    .to_string_lossy()
                    .into_owned(),
            );
        }
    }
    loose.sort();
    assert!(
        loose.len() <= 12,
        "{} files at server/src's root: {loose:?}",
        loose.len()
    );
}
