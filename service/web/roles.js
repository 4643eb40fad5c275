// Roles, as the service orders them: viewer < operator < admin. The page hides or disables what the key's
// role may not do (the API enforces it anyway): elements marked data-needs="operator" or "admin".

const ORDER = { viewer: 1, operator: 2, admin: 3 };
let current = null;

export function setRole(role) {
  current = role;
  for (const node of document.querySelectorAll("[data-needs]")) applyTo(node);
}

/** Whether the signed-in key has at least `role`. */
export function can(role) {
  return current !== null && ORDER[current] >= ORDER[role];
}

/** Disable a control (or hide a section, data-hide) that the key's role may not use. */
export function applyTo(node) {
  const allowed = can(node.dataset.needs);
  if ("hide" in node.dataset) node.hidden = !allowed;
  else if ("disabled" in node) {
    node.disabled = !allowed;
    if (!allowed) node.title = `needs an ${node.dataset.needs} key`;
    else node.removeAttribute("title");
  }
}
