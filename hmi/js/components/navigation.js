// The header's navigation: the screens a user may open, grouped the way an
// operator looks for them (docs/HMI_STYLE.md, "Navigation"), so the header
// stays one row however many panels and drawn screens a plant has.
//
// The first screen (the home screen, Main on most plants) is always a plain
// link, the first of the header. Then a group with one screen is a plain
// link; a group with more is a button that opens a list of links (the
// disclosure pattern of WAI-ARIA, not a menu role: these are links). On a
// phone the groups fold into one "Screens" button, listed under headings.

import { h, replace } from '../dom.js';

/** The groups, in header order. */
export const GROUPS = [
  ['process', 'Process'],
  ['alarms', 'Alarms & events'],
  ['trends', 'Trends'],
  ['engineering', 'Engineering'],
  ['administration', 'Administration'],
];

/** The group of a screen entry of /api/screens (the server says; Process if it does not). */
export function groupOf(entry) {
  return GROUPS.some(([id]) => id === entry.group) ? entry.group : 'process';
}

/**
 * Draws the navigation into `nav` for `screens` ([{id, label, group}], in
 * the server's order) and returns `mark(currentId)`, which shows where the
 * user is. Menus close on a choice, Escape, or a click elsewhere.
 */
export function drawNavigation(nav, screens) {
  const [home, ...rest] = screens;
  const groups = GROUPS.map(([id, label]) => ({ id, label, screens: rest.filter((s) => s.group === id) }))
    .filter((g) => g.screens.length > 0);
  const link = (s) => h('a', { href: `#/${s.id}`, class: 'tool', dataset: { screen: s.id }, text: s.label });
  const buttons = [];
  const closeAll = (except) => {
    for (const b of buttons) if (b !== except) setOpen(b, false);
  };

  const items = groups.map((g) => {
    const heading = h('span', { class: 'tool-group-heading', text: g.label, 'aria-hidden': 'true' });
    if (g.screens.length === 1) {
      return h('div', { class: 'tool-group tool-group-single', dataset: { group: g.id } }, heading, link(g.screens[0]));
    }
    const listId = `nav-${g.id}`;
    const button = h('button', {
      type: 'button', class: 'tool tool-menu-button', 'aria-expanded': 'false', 'aria-controls': listId,
      dataset: { group: g.id },
    }, h('span', { class: 'tool-group-label', text: g.label }), h('span', { class: 'tool-where' }),
    h('span', { class: 'tool-caret', 'aria-hidden': 'true', text: '▾' }));
    const list = h('ul', { id: listId, class: 'tool-menu', 'aria-label': g.label },
      g.screens.map((s) => h('li', {}, link(s))));
    buttons.push(button);
    button.addEventListener('click', () => {
      const open = button.getAttribute('aria-expanded') !== 'true';
      closeAll(button);
      setOpen(button, open);
    });
    button.addEventListener('keydown', (e) => {
      if (e.key === 'ArrowDown') {
        e.preventDefault();
        closeAll(button);
        setOpen(button, true);
        list.querySelector('a')?.focus();
      }
    });
    list.addEventListener('keydown', (e) => {
      const links = [...list.querySelectorAll('a')];
      const at = links.indexOf(document.activeElement);
      if (e.key === 'Escape') {
        e.preventDefault();
        setOpen(button, false);
        button.focus();
      } else if (e.key === 'ArrowDown' || e.key === 'ArrowUp') {
        e.preventDefault();
        const next = (at + (e.key === 'ArrowDown' ? 1 : -1) + links.length) % links.length;
        links[next].focus();
      }
    });
    return h('div', { class: 'tool-group', dataset: { group: g.id } }, heading, button, list);
  });

  // The phone's single button (CSS shows it below 700 px only).
  const phoneButton = h('button', {
    type: 'button', class: 'tool tool-phone-button', 'aria-expanded': 'false', 'aria-controls': 'nav-groups',
  }, h('span', { class: 'tool-group-label', text: 'Screens' }), h('span', { class: 'tool-where' }),
  h('span', { class: 'tool-caret', 'aria-hidden': 'true', text: '▾' }));
  phoneButton.addEventListener('click', () => {
    const open = phoneButton.getAttribute('aria-expanded') !== 'true';
    closeAll();
    setOpen(phoneButton, open);
  });
  buttons.push(phoneButton);
  if (!home) { replace(nav); return () => {}; }
  const homeLink = link(home);
  homeLink.classList.add('tool-home');
  replace(nav, homeLink, groups.length ? [phoneButton, h('div', { id: 'nav-groups', class: 'tool-groups' }, items)] : []);

  nav.onkeydown = (e) => {
    if (e.key === 'Escape' && buttons.some((b) => b.getAttribute('aria-expanded') === 'true')) {
      const phoneOpen = phoneButton.getAttribute('aria-expanded') === 'true';
      closeAll();
      if (phoneOpen) phoneButton.focus();
    }
  };
  // A click anywhere outside the navigation, or a choice in it, closes it.
  nav.onclick = (e) => { if (e.target.closest('a')) closeAll(); };
  document.removeEventListener('pointerdown', nav._outside || (() => {}));
  nav._outside = (e) => { if (!nav.contains(e.target)) closeAll(); };
  document.addEventListener('pointerdown', nav._outside);
  // Focus leaving a group (Tab past its last link) closes its list.
  nav.onfocusout = (e) => {
    const group = e.target.closest('.tool-group');
    if (group && !group.contains(e.relatedTarget)) {
      const b = group.querySelector('.tool-menu-button');
      if (b) setOpen(b, false);
    }
  };

  return function mark(currentId) {
    closeAll();
    const current = screens.find((s) => s.id === currentId);
    for (const a of nav.querySelectorAll('a[data-screen]')) {
      if (a.dataset.screen === currentId) a.setAttribute('aria-current', 'page');
      else a.removeAttribute('aria-current');
    }
    const inGroup = current && current !== home;
    for (const b of nav.querySelectorAll('.tool-menu-button')) {
      const here = !!inGroup && b.dataset.group === current.group;
      b.classList.toggle('tool-here', here);
      // The name is the words on the button (WCAG 2.5.3), the current screen's even where it is not shown.
      b.querySelector('.tool-where').textContent = here ? `· ${current.label}` : '';
      b.setAttribute('aria-label', here ? `${groupLabel(b.dataset.group)} · ${current.label}` : groupLabel(b.dataset.group));
    }
    phoneButton.querySelector('.tool-where').textContent = inGroup ? `· ${current.label}` : '';
    phoneButton.classList.toggle('tool-here', !!inGroup);
    phoneButton.setAttribute('aria-label', inGroup ? `Screens · ${current.label}` : 'Screens');
  };
}

function groupLabel(id) { return (GROUPS.find(([g]) => g === id) || [id, id])[1]; }

function setOpen(button, open) {
  button.setAttribute('aria-expanded', String(open));
  button.closest('.toolbar, .tool-group')?.classList.toggle('tool-open', open);
}
