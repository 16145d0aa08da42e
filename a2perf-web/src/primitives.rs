//! The 40 gMiniWoB design primitives and the two control symbols of A2Perf's generator.

use std::fmt;

/// How a primitive's profile value is drawn at every episode start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProfileValue {
    /// Always the same string.
    Fixed(&'static str),
    /// One of these, uniformly.
    OneOf(&'static [&'static str]),
}

/// Static facts about one primitive (from the reference table).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PrimitiveInfo {
    /// A2Perf primitive name (as in the design files, including the original's typos).
    pub name: &'static str,
    /// The JS concept name; for active primitives this is the profile key.
    pub concept: &'static str,
    /// Whether the primitive adds a profile field that counts in the reward.
    pub active: bool,
    /// The profile value (active primitives only).
    pub value: Option<ProfileValue>,
    /// Whether clicking one of its actionable elements ends the episode with −1.
    pub distractor: bool,
    /// `num_dom_elements` of A2Perf's `PRIMITIVE_INFO_DICT`, used by the difficulty formula.
    pub n_dom: u32,
}

const fn active(
    name: &'static str,
    concept: &'static str,
    v: ProfileValue,
    n: u32,
) -> PrimitiveInfo {
    PrimitiveInfo {
        name,
        concept,
        active: true,
        value: Some(v),
        distractor: false,
        n_dom: n,
    }
}

const fn passive(
    name: &'static str,
    concept: &'static str,
    distractor: bool,
    n: u32,
) -> PrimitiveInfo {
    PrimitiveInfo {
        name,
        concept,
        active: false,
        value: None,
        distractor,
        n_dom: n,
    }
}

use ProfileValue::{Fixed, OneOf};

/// The 40 primitives, sorted by name (the order of A2Perf's `CONCEPTS` minus `#none#`).
pub const PRIMITIVES: [PrimitiveInfo; 40] = [
    active(
        "addressline1",
        "address_line1",
        Fixed("413 E Mountain View"),
        21,
    ),
    active("addressline2", "address_line2", Fixed("2042"), 12),
    active("cabin", "cabin", OneOf(&["Economy", "First"]), 12),
    active("captcha", "captcha", Fixed("CaPtChA"), 13),
    passive("carousel", "carousel", true, 13),
    passive("cart", "cart", true, 13),
    active(
        "cc",
        "credit_card_type",
        OneOf(&["Credit Card", "Debit Card"]),
        17,
    ),
    active("cccvv", "credit_card_verification_code", Fixed("123"), 13),
    active("ccexpdate", "credit_card_expiration", Fixed("2025"), 12),
    active(
        "ccnumber",
        "credit_card_number",
        Fixed("0000 0000 0000 0000"),
        12,
    ),
    active("city", "city", Fixed("Mountain View"), 12),
    passive("dealmedia", "dealmedia", true, 12),
    passive("deck", "deck", true, 13),
    active(
        "departureairport",
        "departureairport",
        Fixed("San Francisco Airport (SFO)"),
        12,
    ),
    active("departuredate", "departuredate", Fixed("10/02/2020"), 12),
    active(
        "destinationairport",
        "destinationairport",
        Fixed("Los Angeles Airport (LAX)"),
        13,
    ),
    active(
        "destinationdate",
        "destinationdate",
        Fixed("10/03/2020"),
        13,
    ),
    active("firstname", "name_first", Fixed("John"), 13),
    active(
        "flighttype",
        "flighttype",
        OneOf(&["Oneway", "Roundtrip"]),
        13,
    ),
    passive("footer1", "footer", true, 12),
    passive("forgotpassowrd", "forgotpassword", true, 67),
    passive("forgotusername", "forgotusername", true, 16),
    active("fullname", "name_full", Fixed("John Wick"), 12),
    passive("header", "header", false, 13),
    passive("header_login", "header", false, 47),
    passive("header_select_items", "header", false, 19),
    passive("inpgroup1", "inputgroup", false, 12),
    active("lastname", "name_last", Fixed("Wick"), 18),
    passive("navbar", "navbar", true, 10),
    passive("next_checkout", "next", false, 13),
    passive("next_login", "next", false, 13),
    passive("next_login_page", "next", false, 20),
    active(
        "numberofpeople",
        "numberofpeople",
        OneOf(&["1", "2", "3", "4", "5"]),
        10,
    ),
    active("password", "password", Fixed("pass"), 13),
    active("rememberme", "rememberme", OneOf(&["true", "false"]), 13),
    active("state", "state", OneOf(&["CA", "NY"]), 12),
    active(
        "stayloggedin",
        "stayloggedin",
        OneOf(&["true", "false"]),
        13,
    ),
    passive("submit", "submit", false, 12),
    active("username", "username", Fixed("john@email.com"), 19),
    active("zipcode", "postal_code", Fixed("95123"), 13),
];

/// A2Perf's "stop" symbol (`#none#`).
pub const STOP: &str = "#none#";
/// A2Perf's "start a new page" symbol (`#next_page#`).
pub const NEXT_PAGE: &str = "#next_page#";

/// One of the 40 design primitives, by its index in [`PRIMITIVES`].
///
/// ```
/// use a2perf_web::Primitive;
/// let p = Primitive::from_name("username").unwrap();
/// assert!(p.info().active);
/// assert_eq!(p.info().concept, "username");
/// assert_eq!(Primitive::ALL.len(), 40);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Primitive(u8);

impl Primitive {
    /// All 40 primitives in name order.
    pub const ALL: [Primitive; 40] = {
        let mut a = [Primitive(0); 40];
        let mut i = 0;
        while i < 40 {
            a[i] = Primitive(i as u8);
            i += 1;
        }
        a
    };

    /// The primitive called `name` (A2Perf spelling).
    pub fn from_name(name: &str) -> Option<Self> {
        PRIMITIVES
            .iter()
            .position(|p| p.name == name)
            .map(|i| Primitive(i as u8))
    }

    /// Its static facts.
    pub fn info(self) -> &'static PrimitiveInfo {
        &PRIMITIVES[usize::from(self.0)]
    }

    /// Index in [`PRIMITIVES`].
    pub fn index(self) -> usize {
        usize::from(self.0)
    }

    /// A2Perf name.
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// Whether it is inserted into the page's form (inputs, buttons, links) rather than above it
    /// (navbar, carousel, deck, header, cart, deal, footer), as in `env-design.js`.
    pub fn in_form(self) -> bool {
        !matches!(
            self.name(),
            "navbar"
                | "carousel"
                | "deck"
                | "header"
                | "header_login"
                | "header_select_items"
                | "cart"
                | "dealmedia"
                | "footer1"
        )
    }
}

impl fmt::Display for Primitive {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_matches_reference_counts() {
        assert_eq!(PRIMITIVES.iter().filter(|p| p.active).count(), 24);
        assert_eq!(PRIMITIVES.iter().filter(|p| !p.active).count(), 16);
        let distractors: Vec<_> = PRIMITIVES
            .iter()
            .filter(|p| p.distractor)
            .map(|p| p.name)
            .collect();
        assert_eq!(
            distractors,
            [
                "carousel",
                "cart",
                "dealmedia",
                "deck",
                "footer1",
                "forgotpassowrd",
                "forgotusername",
                "navbar"
            ]
        );
        let mut names: Vec<_> = PRIMITIVES.iter().map(|p| p.name).collect();
        let sorted = {
            let mut s = names.clone();
            s.sort_unstable();
            s
        };
        assert_eq!(names, sorted);
        names.dedup();
        assert_eq!(names.len(), 40);
        // Profile keys are unique among active primitives.
        let mut keys: Vec<_> = PRIMITIVES
            .iter()
            .filter(|p| p.active)
            .map(|p| p.concept)
            .collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), 24);
    }
}
