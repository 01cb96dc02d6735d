//! The layering of both crates, read from their sources: no module reaches a module that
//! reaches it back (through `crate::` paths), nothing outside the HTTP layer names `routes`
//! (apart from where the app is assembled), the store never names the HTTP error type, and the
//! routes hold no SQL. A text check, like a reviewer's: cheap, and it fails the build the day a
//! circle comes back.

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

#[test]
fn the_http_layer_stays_in_its_place() {
    let mods = modules(&crate_src("server"));
    let assembly = ["", "app", "cli::service"];
    let sql = [
        "sqlx::query",
        "\"SELECT",
        "\"INSERT INTO",
        "\"DELETE FROM",
        "\"UPDATE ",
    ];
    for (module, (path, text)) in &mods {
        let in_routes = module == "routes" || module.starts_with("routes::");
        let in_store = module == "store" || module.starts_with("store::");
        if !in_routes && !assembly.contains(&module.as_str()) {
            assert!(
                !text.contains("crate::routes"),
                "{} names the HTTP layer",
                path.display()
            );
        }
        if in_store {
            assert!(
                !text.contains("crate::error")
                    && !text.contains("AppError")
                    && !text.contains("axum"),
                "{} (the store) names the HTTP error type or axum",
                path.display()
            );
        }
        if in_routes {
            for s in sql {
                assert!(
                    !text.contains(s),
                    "{} (the HTTP layer) holds SQL: {s}",
                    path.display()
                );
            }
        }
    }
}
