// The theme chosen in this browser (light, or dark for control rooms), set
// before the first paint so a dark room never sees a white flash. A classic
// script from 'self' (the CSP allows no inline script); app.js owns the toggle.
try {
  if (localStorage.getItem('gridscada.theme') === 'dark') document.documentElement.dataset.theme = 'dark';
} catch (e) { /* storage disabled: the light theme */ }
