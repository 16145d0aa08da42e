//! The dynamic state of a website's DOM, the simulated backend's action semantics and its
//! deterministic block layout.
//!
//! The same [`DomState`] is filled by the Chromium backend from the real browser, so observations
//! and rewards are computed by one piece of code for both backends.

use crate::site::{
    Behaviour, Block, FALSE_ID, FieldKind, ONE_ID, PAD, ROOT_WIDTH, TRUE_ID, Tag, Website,
};

/// What an action triggered on the page.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Event {
    /// Nothing that ends the episode.
    #[default]
    None,
    /// A distractor was clicked (episode ends with −1).
    Distractor,
    /// The form was submitted.
    Submit,
}

/// What an action does to its element.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActionKind {
    /// Click the element (as a user would: controls take the focus, a radio is checked).
    Click,
    /// Type a value (string id) into the element.
    Type(u32),
    /// A2Perf's `visitGroup(id, value)` with an optional value (string id), the original's only
    /// way of acting on a page: it acts on the first element carrying the element's `id`, and only
    /// when that one is visible; it marks it `visited`; text/number/password inputs and selects get
    /// the value (none clears them); a radio checks the button of its group holding the value
    /// (none checks nothing) and marks the group visited; a checkbox is clicked (toggled) only
    /// when the value is JavaScript-true (`true`, or `"1"` by loose equality); anything else is
    /// clicked; elements without an id are left alone; nothing takes the focus.
    Visit(Option<u32>),
}

/// Behaviours of the original A2Perf that the page reproduces on request.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Quirks {
    /// A2Perf's radio-group lookup: the group is found from the concept between the first two
    /// `_` of the radio's id, which is `credit` for `actionable_credit_card_type_p0_i0`, so the
    /// `cc` (credit-card type) group is never found: acting on one of its buttons only marks that
    /// button `visited` and never checks anything (the original's `cc` bug).
    pub cc_bug: bool,
    /// Render an active primitive again when a later page repeats it, as the original did:
    /// a text input, select or checkbox copy shares the first copy's id, so the original read and
    /// acted on the first one only (the copy holds no field); a radio-group copy has ids of its
    /// own and works (its buttons join the field and share the first group's `name`).
    pub duplicate_fields: bool,
}

/// Dynamic state of every element.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DomState {
    /// Current page.
    pub page: u16,
    /// Own `display: none` flag (pages, navbar menus, carousel slides).
    pub hidden: Vec<bool>,
    /// Rendered (the element and all its ancestors are displayed).
    pub visible: Vec<bool>,
    /// Has the `visited` class.
    pub visited: Vec<bool>,
    /// Checkbox/radio checked.
    pub checked: Vec<bool>,
    /// Value string id of inputs and selects.
    pub value: Vec<u32>,
    /// Focused element.
    pub focused: Option<u32>,
    /// Visible elements in document order.
    pub order: Vec<u32>,
    /// `[x, y, width, height]` relative to the website root, px (valid for visible elements).
    pub rect: Vec<[f32; 4]>,
    /// First episode-ending event so far.
    pub event: Event,
}

/// Whether `s` is an HTML "valid floating-point number" (what `<input type=number>` keeps).
pub fn is_valid_number(s: &str) -> bool {
    let b = s.as_bytes();
    let mut i = 0;
    if b.first() == Some(&b'-') {
        i += 1;
    }
    let int_start = i;
    while i < b.len() && b[i].is_ascii_digit() {
        i += 1;
    }
    let int_digits = i - int_start;
    let mut frac_digits = 0;
    if i < b.len() && b[i] == b'.' {
        i += 1;
        let s = i;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        frac_digits = i - s;
        if frac_digits == 0 {
            return false;
        }
    }
    if int_digits + frac_digits == 0 {
        return false;
    }
    if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
        i += 1;
        if i < b.len() && (b[i] == b'-' || b[i] == b'+') {
            i += 1;
        }
        let s = i;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        if i == s {
            return false;
        }
    }
    i == b.len()
}

impl DomState {
    /// Initial state of `site` (first page shown, nothing visited), with layout.
    pub fn reset(&mut self, site: &Website) {
        let n = site.nodes.len();
        self.page = 0;
        self.hidden.clear();
        self.hidden.extend(site.nodes.iter().map(|n| n.hidden));
        self.visible.clear();
        self.visible.resize(n, false);
        self.visited.clear();
        self.visited.resize(n, false);
        self.checked.clear();
        self.checked.resize(n, false);
        self.value.clear();
        self.value.extend((0..n).map(|i| site.initial_value(i)));
        self.focused = None;
        self.order.clear();
        self.order.reserve(n);
        self.rect.clear();
        self.rect.resize(n, [0.0; 4]);
        self.event = Event::None;
        self.layout(site);
    }

    /// Copies `other` into `self` without allocating (once capacities suffice).
    pub fn copy_from(&mut self, other: &DomState) {
        self.page = other.page;
        self.hidden.clone_from(&other.hidden);
        self.visible.clone_from(&other.visible);
        self.visited.clone_from(&other.visited);
        self.checked.clone_from(&other.checked);
        self.value.clone_from(&other.value);
        self.focused = other.focused;
        self.order.clone_from(&other.order);
        self.rect.clone_from(&other.rect);
        self.event = other.event;
    }

    /// Whether an agent would see the same page (elements, their values, classes and focus).
    pub fn same_view(&self, other: &DomState) -> bool {
        self.order == other.order
            && self.focused == other.focused
            && self.order.iter().all(|&i| {
                let i = i as usize;
                self.visited[i] == other.visited[i]
                    && self.checked[i] == other.checked[i]
                    && self.value[i] == other.value[i]
            })
    }

    /// Recomputes visibility, document order and boxes of the imposed block layout: containers
    /// have 2 px padding and stack their displayed children, leaves have a fixed height, every
    /// element is as wide as its parent's content box, the root is 375 px wide.
    pub fn layout(&mut self, site: &Website) {
        self.visible.iter_mut().for_each(|v| *v = false);
        self.order.clear();
        let mut y = 0.0;
        let mut j = 0;
        while j < site.nodes.len() {
            let next = site.nodes[j].end as usize;
            if !self.hidden[j] {
                y += self.lay(site, j, 0.0, y, ROOT_WIDTH);
            }
            j = next;
        }
    }

    fn lay(&mut self, site: &Website, i: usize, x: f32, y: f32, w: f32) -> f32 {
        self.visible[i] = true;
        self.order.push(i as u32);
        let n = &site.nodes[i];
        let h = match n.block {
            Block::Leaf(h) => f32::from(h),
            Block::Container => {
                let mut cy = y + PAD;
                let mut j = i + 1;
                let end = n.end as usize;
                while j < end {
                    let next = site.nodes[j].end as usize;
                    if !self.hidden[j] {
                        cy += self.lay(site, j, x + PAD, cy, w - 2.0 * PAD);
                    }
                    j = next;
                }
                cy + PAD - y
            }
        };
        self.rect[i] = [x, y, w, h];
        h
    }

    /// String id of element `i`'s observed value: `true`/`false` for checkboxes and radios, the
    /// value of other controls, `""` otherwise.
    pub fn value_id(&self, site: &Website, i: usize) -> u32 {
        let tag = site.nodes[i].tag;
        if tag.is_toggle() {
            if self.checked[i] { TRUE_ID } else { FALSE_ID }
        } else if tag.is_control() {
            self.value[i]
        } else {
            0
        }
    }

    /// Whether profile field `f` currently holds its gold value.
    pub fn field_correct(&self, site: &Website, f: usize) -> bool {
        let field = &site.fields[f];
        match field.kind {
            FieldKind::Text => self.value[field.nodes[0] as usize] == field.value_id,
            FieldKind::Check => {
                self.checked[field.nodes[0] as usize] == (field.value_id == TRUE_ID)
            }
            FieldKind::Radio => field.nodes.iter().any(|&n| {
                self.checked[n as usize] && site.nodes[n as usize].radio_value == field.value_id
            }),
        }
    }

    /// Whether the agent has acted on field `f`'s element(s).
    pub fn field_visited(&self, site: &Website, f: usize) -> bool {
        site.fields[f]
            .nodes
            .iter()
            .any(|&n| self.visited[n as usize])
    }

    /// Potential Φ: share of fields that were visited and hold their gold value (gMiniWoB's
    /// `potential(true)`); 0 for a website without fields.
    pub fn potential(&self, site: &Website) -> f64 {
        let n = site.fields.len();
        if n == 0 {
            return 0.0;
        }
        let ok = (0..n)
            .filter(|&f| self.field_visited(site, f) && self.field_correct(site, f))
            .count();
        ok as f64 / n as f64
    }

    /// Whether submitting now succeeds (every field correct; visiting not required, as in
    /// `computeFormReward`).
    pub fn all_correct(&self, site: &Website) -> bool {
        (0..site.fields.len()).all(|f| self.field_correct(site, f))
    }

    /// Checks radio `i`, unchecking the others of its `name` (every copy of its field's group).
    fn check_radio(&mut self, site: &Website, i: usize) {
        let node = &site.nodes[i];
        let same_name = match (node.field, node.group) {
            (Some(f), _) => site.fields[usize::from(f)].nodes.as_slice(),
            (None, Some(g)) => site.radio_group(g),
            (None, None) => &[],
        };
        for &r in same_name {
            self.checked[r as usize] = false;
        }
        self.checked[i] = true;
    }

    /// Whether acting on radio `i` finds its group (always, unless `quirks.cc_bug` and the
    /// group's concept cannot be read from the radio's id).
    fn radio_group_found(site: &Website, i: usize, quirks: Quirks) -> bool {
        !quirks.cc_bug || site.nodes[i].group_from_id
    }

    /// What a click does besides focus: toggles a checkbox, checks a radio, and triggers the
    /// element's behaviour (distractor, submit, next page, menu toggle).
    fn press(&mut self, site: &Website, i: usize, quirks: Quirks) {
        let node = &site.nodes[i];
        match node.tag {
            Tag::InputCheckbox => self.checked[i] = !self.checked[i],
            Tag::InputRadio if Self::radio_group_found(site, i, quirks) => {
                self.check_radio(site, i)
            }
            _ => {}
        }
        match node.behaviour {
            Behaviour::Distractor if self.event == Event::None => {
                self.event = Event::Distractor;
            }
            Behaviour::Submit if self.event == Event::None => self.event = Event::Submit,
            Behaviour::Next(p) if p == self.page && usize::from(p) + 1 < site.pages.len() => {
                self.focused = None;
                self.hidden[site.pages[usize::from(p)] as usize] = true;
                self.hidden[site.pages[usize::from(p) + 1] as usize] = false;
                self.page = p + 1;
                self.layout(site);
            }
            Behaviour::Toggle(t) => {
                self.hidden[t as usize] = !self.hidden[t as usize];
                self.layout(site);
            }
            _ => {}
        }
    }

    /// Sets the value of a text/number/password input or a select as the browser does: a
    /// number input keeps only valid numbers, a select only one of its options (else `""`).
    fn set_value(&mut self, site: &Website, i: usize, v: u32) {
        let node = &site.nodes[i];
        self.value[i] = match node.tag {
            Tag::Select if !node.options.contains(&v) => 0,
            Tag::InputNumber
                if !site
                    .strings
                    .get(v as usize)
                    .is_some_and(|s| is_valid_number(s)) =>
            {
                0
            }
            _ => v,
        };
    }

    /// Checks the radio of `i`'s group whose value is `v` and marks the group visited (or, when
    /// the group cannot be found, marks only `i`).
    fn set_radio(&mut self, site: &Website, i: usize, v: Option<u32>, quirks: Quirks) {
        let Some(g) = site.nodes[i]
            .group
            .filter(|_| Self::radio_group_found(site, i, quirks))
        else {
            self.visited[i] = true;
            return;
        };
        for &r in site.radio_group(g) {
            let r = r as usize;
            if Some(site.nodes[r].radio_value) == v {
                self.check_radio(site, r);
            }
            self.visited[r] = true;
        }
    }

    /// Applies an action to element `i` with the simulated backend (the same rules as the page
    /// script in [`crate::site::SCRIPT`]). Invisible targets are ignored.
    pub fn apply(&mut self, site: &Website, i: usize, kind: ActionKind, quirks: Quirks) {
        if let ActionKind::Visit(v) = kind {
            self.visit(site, i, v, quirks);
            return;
        }
        if !self.visible.get(i).copied().unwrap_or(false) {
            return;
        }
        let node = &site.nodes[i];
        match kind {
            ActionKind::Click => {
                if node.tag.is_control() {
                    self.focused = Some(i as u32);
                }
                self.press(site, i, quirks);
                if node.actionable() {
                    self.visited[i] = true;
                }
            }
            ActionKind::Type(v) => {
                if !node.tag.is_control() {
                    return;
                }
                match node.tag {
                    Tag::InputCheckbox => self.checked[i] = v == TRUE_ID,
                    Tag::InputRadio => self.set_radio(site, i, Some(v), quirks),
                    _ => self.set_value(site, i, v),
                }
                self.focused = Some(i as u32);
                if node.actionable() {
                    self.visited[i] = true;
                }
            }
            ActionKind::Visit(_) => {}
        }
    }

    /// A2Perf's `visitGroup` (see [`ActionKind::Visit`]).
    fn visit(&mut self, site: &Website, i: usize, v: Option<u32>, quirks: Quirks) {
        let Some(&owner) = site.id_owner.get(i) else {
            return;
        };
        let i = owner as usize;
        if site.nodes[i].html_id.is_empty() || !self.visible[i] {
            return;
        }
        self.visited[i] = true;
        match site.nodes[i].tag {
            Tag::InputText | Tag::InputPassword | Tag::InputNumber | Tag::Select => {
                self.set_value(site, i, v.unwrap_or(0));
            }
            Tag::InputRadio => self.set_radio(site, i, v, quirks),
            Tag::InputCheckbox => {
                if matches!(v, Some(TRUE_ID | ONE_ID)) {
                    self.press(site, i, quirks);
                }
            }
            _ => self.press(site, i, quirks),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn number_validation_follows_html() {
        for ok in ["1", "2042", "-3", "0.5", ".5", "1e3", "95123"] {
            assert!(is_valid_number(ok), "{ok}");
        }
        for bad in [
            "",
            "-",
            "1.",
            "+1",
            "0000 0000",
            "10/02/2020",
            "true",
            "e3",
            "1e",
        ] {
            assert!(!is_valid_number(bad), "{bad}");
        }
    }
}
