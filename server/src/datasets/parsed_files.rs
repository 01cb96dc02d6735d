//! Result files parsed once for the pictures of their targets. A submission's gallery asks for
//! a dozen pictures at once, and each used to fetch the stored upload and parse all of it: for a
//! paper-sized file the parse costs more than the drawing. Uploads are stored under their
//! SHA-256 and never change, so an entry is never stale. The most recently used files are kept
//! up to a memory budget (the newest always, whatever its size), and parsing is single-flight:
//! while one request parses a file, the others asking for it wait for that parse.

use std::collections::VecDeque;
use std::future::Future;
use std::sync::{Arc, Mutex, MutexGuard};

use evaluator::results::{Estimate, Results};
use tokio::sync::OnceCell;

/// Memory for parsed files in a server: about 1.7 million estimates, a dozen paper-sized files.
pub const DEFAULT_BUDGET: usize = 256 << 20;

type Entry = (String, Arc<OnceCell<Arc<Results>>>);

pub struct ParsedFiles {
    budget: usize,
    /// Most recently used first.
    entries: Mutex<VecDeque<Entry>>,
}

impl ParsedFiles {
    pub fn new(budget: usize) -> Self {
        ParsedFiles {
            budget,
            entries: Mutex::new(VecDeque::new()),
        }
    }

    /// The parsed file stored under `sha256`, from memory or from `parse` (whose failure is
    /// returned and not remembered: the next request tries again).
    pub async fn get_or_parse<E, F, Fut>(&self, sha256: &str, parse: F) -> Result<Arc<Results>, E>
    where
        F: FnOnce() -> Fut,
        Fut: Future<Output = Result<Results, E>>,
    {
        let cell = {
            let mut entries = self.lock();
            let cell = match entries.iter().position(|(key, _)| key == sha256) {
                Some(i) => entries.remove(i).expect("position is in range").1,
                None => Arc::new(OnceCell::new()),
            };
            entries.push_front((sha256.to_owned(), cell.clone()));
            cell
        };
        let parsed = cell
            .get_or_try_init(|| async { parse().await.map(Arc::new) })
            .await
            .cloned();
        let mut entries = self.lock();
        match &parsed {
            Ok(_) => self.trim(&mut entries),
            Err(_) => entries.retain(|(_, c)| !(Arc::ptr_eq(c, &cell) && c.get().is_none())),
        }
        parsed
    }

    /// Drops the least recently used files beyond the budget; the newest stays.
    fn trim(&self, entries: &mut VecDeque<Entry>) {
        let mut used = 0usize;
        let mut keep = 0;
        for (i, (_, cell)) in entries.iter().enumerate() {
            used = used.saturating_add(cell.get().map_or(0, |r| footprint(r)));
            if i > 0 && used > self.budget {
                break;
            }
            keep = i + 1;
        }
        entries.truncate(keep);
    }

    /// Drops the parse of `sha256`, a file no submission has any longer: no picture will ask
    /// for it again, and a service whose users replace their uploads would otherwise hold their
    /// deleted files until the budget pushed them out, its memory growing for hours.
    pub fn forget(&self, sha256: &str) {
        self.lock().retain(|(key, _)| key != sha256);
    }

    /// The hashes held, most recently used first.
    pub fn held(&self) -> Vec<String> {
        self.lock().iter().map(|(key, _)| key.clone()).collect()
    }

    fn lock(&self) -> MutexGuard<'_, VecDeque<Entry>> {
        // The queue is only reordered under the lock, never left half-changed by a panic.
        self.entries.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Bytes a parsed file holds, near enough to budget by.
fn footprint(r: &Results) -> usize {
    r.estimates.capacity() * std::mem::size_of::<Estimate>()
        + r.image_times.len() * (std::mem::size_of::<((u32, u32), f64)>() + 16)
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::*;

    fn file(lines: usize) -> Results {
        let mut csv = String::from("scene_id,im_id,obj_id,score,R,t,time\n");
        for i in 0..lines {
            csv += &format!("1,{i},1,0.5,1 0 0 0 1 0 0 0 1,0 0 500,0.1\n");
        }
        evaluator::results::parse_results(csv.as_bytes()).expect("a valid file")
    }

    #[tokio::test]
    async fn a_file_is_parsed_once_and_failures_are_not_kept() {
        let cache = ParsedFiles::new(DEFAULT_BUDGET);
        let parses = &AtomicUsize::new(0);
        let parse = move || async move {
            parses.fetch_add(1, Ordering::SeqCst);
            Ok::<_, String>(file(3))
        };
        let a = cache.get_or_parse("a", parse).await.unwrap();
        let b = cache.get_or_parse("a", parse).await.unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        assert_eq!(parses.load(Ordering::SeqCst), 1);
        assert_eq!(a.estimates.len(), 3);

        let failed = cache
            .get_or_parse("b", || async { Err::<Results, _>("gone".to_owned()) })
            .await;
        assert_eq!(failed.unwrap_err(), "gone");
        assert_eq!(cache.held(), ["a"]);
        let b = cache.get_or_parse("b", parse).await.unwrap();
        assert_eq!(b.estimates.len(), 3);
        assert_eq!(parses.load(Ordering::SeqCst), 2);
    }

    #[tokio::test]
    async fn the_least_recently_used_go_beyond_the_budget_but_never_the_newest() {
        let one = footprint(&file(100));
        let cache = ParsedFiles::new(2 * one + one / 2);
        for key in ["a", "b", "c"] {
            cache
                .get_or_parse(key, || async { Ok::<_, ()>(file(100)) })
                .await
                .unwrap();
        }
        assert_eq!(cache.held(), ["c", "b"]);
        // Using b makes it the newest; the next file pushes c out.
        cache
            .get_or_parse("b", || async { Err::<Results, ()>(()) })
            .await
            .unwrap();
        cache
            .get_or_parse("d", || async { Ok::<_, ()>(file(100)) })
            .await
            .unwrap();
        assert_eq!(cache.held(), ["d", "b"]);

        let tiny = ParsedFiles::new(1);
        tiny.get_or_parse("big", || async { Ok::<_, ()>(file(100)) })
            .await
            .unwrap();
        assert_eq!(tiny.held(), ["big"]);
    }

    #[tokio::test]
    async fn a_forgotten_file_is_dropped_and_parsed_again_when_asked_for() {
        let cache = ParsedFiles::new(DEFAULT_BUDGET);
        let parses = &AtomicUsize::new(0);
        let parse = move || async move {
            parses.fetch_add(1, Ordering::SeqCst);
            Ok::<_, ()>(file(3))
        };
        for key in ["a", "b"] {
            cache.get_or_parse(key, parse).await.unwrap();
        }
        cache.forget("a");
        assert_eq!(cache.held(), ["b"]);
        cache.forget("never held");
        assert_eq!(cache.held(), ["b"]);
        cache.get_or_parse("a", parse).await.unwrap();
        assert_eq!(parses.load(Ordering::SeqCst), 3);
    }

    #[tokio::test]
    async fn concurrent_requests_share_one_parse() {
        let cache = Arc::new(ParsedFiles::new(DEFAULT_BUDGET));
        let parses = Arc::new(AtomicUsize::new(0));
        let mut tasks = Vec::new();
        for _ in 0..8 {
            let (cache, parses) = (cache.clone(), parses.clone());
            tasks.push(tokio::spawn(async move {
                cache
                    .get_or_parse("a", move || async move {
                        parses.fetch_add(1, Ordering::SeqCst);
                        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
                        Ok::<_, ()>(file(10))
                    })
                    .await
                    .unwrap()
                    .estimates
                    .len()
            }));
        }
        for t in tasks {
            assert_eq!(t.await.unwrap(), 10);
        }
        assert_eq!(parses.load(Ordering::SeqCst), 1);
    }
}
