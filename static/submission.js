// Follows a queued or running submission every second (place in the queue, estimates done,
// when the scores are expected) and reloads the page once it is finished.
(function () {
  const box = document.getElementById("status");
  if (!box) return;
  const state = box.dataset.status;
  if (state !== "queued" && state !== "running") return;
  const bar = document.getElementById("progress");
  const text = document.getElementById("status-text");
  const detail = document.getElementById("progress-text");
  async function poll() {
    try {
      const r = await fetch("/api/v1/submissions/" + box.dataset.id, { headers: { Accept: "application/json" } });
      if (r.ok) {
        const s = await r.json();
        bar.value = s.progress;
        text.textContent = s.status + (s.status === "running" ? " " + Math.round(s.progress * 100) + " %" : "");
        text.className = "status " + s.status;
        detail.textContent = s.progress_text ? "· " + s.progress_text : "";
        if (s.status === "done" || s.status === "failed") { location.reload(); return; }
      }
    } catch (e) { /* the next poll retries */ }
    setTimeout(poll, 1000);
  }
  setTimeout(poll, 1000);
})();
