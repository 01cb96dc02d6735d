// Small behaviours of every page, without inline scripts (the content security policy forbids
// them): forms marked data-confirm ask before they submit, buttons marked data-copy copy the
// text of the element they name.
(function () {
  document.addEventListener("submit", function (e) {
    const message = e.target.dataset && e.target.dataset.confirm;
    if (message && !window.confirm(message)) e.preventDefault();
  });
  document.addEventListener("click", async function (e) {
    const button = e.target.closest && e.target.closest("button[data-copy]");
    if (!button) return;
    const source = document.getElementById(button.dataset.copy);
    if (!source) return;
    const label = button.textContent;
    try {
      await navigator.clipboard.writeText(source.textContent);
      button.textContent = "Copied";
    } catch (err) {
      // No clipboard access (an insecure origin): select the text for the reader to copy.
      const range = document.createRange();
      range.selectNodeContents(source);
      const selection = window.getSelection();
      selection.removeAllRanges();
      selection.addRange(range);
      button.textContent = "Selected: press Ctrl+C";
    }
    setTimeout(function () { button.textContent = label; }, 2000);
  });
})();
