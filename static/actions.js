// Small behaviours of every page, without inline scripts (the content security policy forbids
// them): the menu follows sign-in, forms marked data-confirm ask before they submit, buttons
// marked data-copy copy the text of the element they name.
(function () {
  // The pb_signed_in cookie (no secret: it only says a session cookie was set with it) picks
  // the menu's links, on pages that are the same for every reader.
  const signedIn = document.cookie.split("; ").indexOf("pb_signed_in=1") >= 0;
  document.documentElement.classList.add(signedIn ? "signed-in" : "signed-out");
  document.addEventListener("submit", function (e) {
    const message = e.target.dataset && e.target.dataset.confirm;
    if (message && !window.confirm(message)) e.preventDefault();
  });
  document.addEventListener("click", async function (e) {
    const button = e.target.closest && e.target.closest("button[data-copy]");
    if (!button) return;
    const source = document.getElementById(button.dataset.copy);
    if (!source) return;
    const label = button.dataset.label || button.textContent;
    button.dataset.label = label;
    // The text is selected at once, ready for Ctrl+C whatever the clipboard does, and the
    // button answers before the clipboard does (which may never answer on some browsers).
    const range = document.createRange();
    range.selectNodeContents(source);
    const selection = window.getSelection();
    selection.removeAllRanges();
    selection.addRange(range);
    button.textContent = "Copying…";
    let copied = false;
    try {
      await Promise.race([
        navigator.clipboard.writeText(source.textContent),
        new Promise(function (_, reject) { setTimeout(reject, 1000); }),
      ]);
      copied = true;
    } catch (err) {
      // No clipboard access (an insecure origin) or no answer: the selection stays.
    }
    button.textContent = copied ? "Copied" : "Selected: press Ctrl+C";
    setTimeout(function () { button.textContent = label; }, 2000);
  });
})();
