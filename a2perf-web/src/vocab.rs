//! The fixed tokenizer and vocabulary.
//!
//! The original grew its vocabulary while running (ids depended on what was seen first, and on
//! Python's hash seed). Here the vocabulary is every token of every string the website builder can
//! emit, sorted, with `0 = padding` and `1 = out of vocabulary`; it never changes at run time.

use std::collections::HashMap;
use std::sync::OnceLock;

use serde::{Deserialize, Serialize};

use crate::primitives::{PRIMITIVES, ProfileValue};
use crate::site::Tag;

/// Id of the padding token.
pub const PAD_ID: u32 = 0;
/// Id of the out-of-vocabulary token.
pub const OOV_ID: u32 = 1;
/// Size of [`Vocabulary::standard`] (checked by a test).
pub const VOCAB_SIZE: usize = 313;

/// Splits text like A2Perf's `vocabulary_utils.tokenize`: `.` becomes a space, lower-case, then
/// runs of word characters (letters, digits, `_`) or single other non-space characters.
///
/// ```
/// assert_eq!(a2perf_web::tokenize("john@email.com"), ["john", "@", "email", "com"]);
/// assert_eq!(a2perf_web::tokenize("form-control"), ["form", "-", "control"]);
/// assert!(a2perf_web::tokenize("").is_empty());
/// ```
pub fn tokenize(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    for c in text.chars().flat_map(char::to_lowercase) {
        let c = if c == '.' { ' ' } else { c };
        if c.is_alphanumeric() || c == '_' {
            cur.push(c);
        } else {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            if !c.is_whitespace() {
                out.push(c.to_string());
            }
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Every literal the website builder emits (texts, placeholders, classes).
const SOURCE_TEXTS: &[&str] = &[
    "Address",
    "Enter Captcha",
    "CVV",
    "Expiration date",
    "Credit card number",
    "City",
    "From",
    "Depart",
    "To",
    "Return",
    "First Name",
    "Full Name",
    "Last Name",
    "ZIP Code",
    "Number of passengers",
    "Remember me",
    "Stay logged in",
    "Cabin",
    "Payment",
    "Search",
    "Apt #",
    "Username",
    "Password",
    "Promo code",
    "Forgot password.",
    "Forgot user name.",
    "Shipping Information",
    "Login",
    "Select items",
    "GShopping",
    "Menu",
    "Home",
    "Account",
    "Cart",
    "Checkout",
    "Previous",
    "Next",
    "Your cart",
    "Shoe Bag Tshirt Remove Redeem",
    "Deal of the Day",
    "Gaming workstation",
    "Get it today!",
    "Title stars $",
    "2020-2021 The Company.",
    "Contact Terms Support Full Site",
    "Login and Checkout",
    "Place Order",
    "Submit",
    "form-group form-control custom-control custom-checkbox custom-control-input",
    "custom-control-label d-block my-3 mb-3 custom-radio custom-select w-100 input-group",
    "navbar navbar-dark bg-dark navbar-brand navbar-toggler collapse navbar-collapse nav-link",
    "carousel slide carousel-inner carousel-item active carousel-control-prev carousel-control-next",
    "card card-header list-group-item text-muted remove btn btn-secondary media mr-3 media-body",
    "mt-0 card-deck card-img-top card-title card-text footer footer-link page container",
    "btn-sm btn-block btn-primary btn-lg visited no_class true false",
    "cabinroot credit_card_typeroot flighttyperoot",
    // A2Perf's `_dummy` profile field (observation field 0).
    "_dummy",
];

/// A fixed token → id map.
///
/// ```
/// use a2perf_web::{Vocabulary, VOCAB_SIZE, OOV_ID};
/// let v = Vocabulary::standard();
/// assert_eq!(v.len(), VOCAB_SIZE);
/// let ids = v.encode("John Wick");
/// assert_eq!(ids.len(), 2);
/// assert_eq!(v.encode("zzzqqq"), vec![OOV_ID]);
/// ```
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Vocabulary {
    /// Tokens by id (`tokens[0]` = padding, `tokens[1]` = OOV).
    pub tokens: Vec<String>,
    #[serde(skip)]
    index: HashMap<String, u32>,
}

impl Vocabulary {
    /// Builds a vocabulary from a token list (id = position).
    pub fn from_tokens(tokens: Vec<String>) -> Self {
        let index = tokens
            .iter()
            .enumerate()
            .map(|(i, t)| (t.clone(), i as u32))
            .collect();
        Self { tokens, index }
    }

    /// The benchmark's vocabulary.
    pub fn standard() -> &'static Vocabulary {
        static V: OnceLock<Vocabulary> = OnceLock::new();
        V.get_or_init(|| {
            let mut words: Vec<String> = Vec::new();
            let mut add = |s: &str| words.extend(tokenize(s));
            for t in Tag::ALL {
                add(t.token());
            }
            for s in SOURCE_TEXTS {
                add(s);
            }
            for p in PRIMITIVES.iter() {
                add(p.concept);
                match p.value {
                    Some(ProfileValue::Fixed(v)) => add(v),
                    Some(ProfileValue::OneOf(vs)) => vs.iter().for_each(|v| add(v)),
                    None => {}
                }
            }
            for n in 0..=100 {
                add(&n.to_string());
            }
            for n in 0..10 {
                add(&format!("0{n}"));
            }
            words.sort_unstable();
            words.dedup();
            let mut tokens = vec!["<pad>".to_string(), "<oov>".to_string()];
            tokens.extend(words);
            Vocabulary::from_tokens(tokens)
        })
    }

    /// Number of ids.
    pub fn len(&self) -> usize {
        self.tokens.len()
    }

    /// Whether the vocabulary is empty (never for the standard one).
    pub fn is_empty(&self) -> bool {
        self.tokens.is_empty()
    }

    /// The id of one token (OOV when unknown).
    pub fn id(&self, token: &str) -> u32 {
        self.index.get(token).copied().unwrap_or(OOV_ID)
    }

    /// Tokenises and maps `text` to ids.
    pub fn encode(&self, text: &str) -> Vec<u32> {
        tokenize(text).iter().map(|t| self.id(t)).collect()
    }

    /// Serialises the token list as JSON (ids are positions).
    pub fn to_json(&self) -> String {
        serde_json::to_string(&self.tokens).unwrap_or_default()
    }

    /// Reads a token list written by [`Vocabulary::to_json`].
    pub fn from_json(text: &str) -> Result<Self, serde_json::Error> {
        serde_json::from_str::<Vec<String>>(text).map(Self::from_tokens)
    }
}

/// Size of the standard vocabulary (same as [`VOCAB_SIZE`]).
pub fn vocab_size() -> usize {
    Vocabulary::standard().len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokenizer_matches_reference_rules() {
        assert_eq!(tokenize("input_text"), ["input_text"]);
        assert_eq!(tokenize("Forgot password."), ["forgot", "password"]);
        assert_eq!(tokenize("Apt #"), ["apt", "#"]);
        assert_eq!(tokenize("10/02/2020"), ["10", "/", "02", "/", "2020"]);
        assert_eq!(tokenize("$23"), ["$", "23"]);
    }

    #[test]
    fn vocabulary_is_fixed_and_round_trips() {
        let v = Vocabulary::standard();
        assert_eq!(v.len(), VOCAB_SIZE);
        assert_eq!(vocab_size(), VOCAB_SIZE);
        assert_eq!(v.id("<pad>"), PAD_ID);
        let back = Vocabulary::from_json(&v.to_json()).unwrap();
        assert_eq!(back.tokens, v.tokens);
        assert_eq!(back.encode("john@email.com"), v.encode("john@email.com"));
        assert!(v.encode("john@email.com").iter().all(|&i| i > OOV_ID));
    }
}
