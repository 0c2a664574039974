// A classic script: if the page's modules never start (a library missing from
// /ui/vendor/, a browser without module scripts), say so instead of
// "Loading…" forever.
window.addEventListener('load', () => {
  setTimeout(() => {
    if (document.documentElement.dataset.started) return;
    const boot = document.getElementById('boot');
    if (!boot) return;
    boot.className = 'alert error';
    boot.setAttribute('role', 'alert');
    boot.textContent = 'The page’s scripts did not start. If you run this server, install the '
      + 'browser libraries with scripts/install-web.sh; otherwise try a current Firefox or Chromium.';
  }, 4000);
});
