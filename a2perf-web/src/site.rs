//! Concrete websites: the element tree of a design with one episode's random content, and its HTML.
//!
//! Every element is a CSS block whose box is fully determined by the stylesheet written here
//! (containers: 2 px padding, leaves: fixed height, full width, no margins or borders), so the
//! simulated layout in [`crate::dom`] reproduces Chromium's `getBoundingClientRect` exactly.

use std::collections::HashMap;
use std::fmt::Write as _;

use a2perf_core::RngStream;

use crate::design::Design;
use crate::dom::{DomState, Quirks};
use crate::primitives::{Primitive, ProfileValue};
use crate::vocab::Vocabulary;

/// Element kinds (the observation's `tag` attribute is [`Tag::token`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tag {
    /// `<div>`
    Div,
    /// `<nav>`
    Nav,
    /// `<footer>`
    Footer,
    /// `<h5>`
    H5,
    /// `<h6>`
    H6,
    /// `<p>`
    P,
    /// `<span>`
    Span,
    /// `<a>`
    A,
    /// `<label>`
    Label,
    /// `<button>`
    Button,
    /// `<img>`
    Img,
    /// `<input type=text>`
    InputText,
    /// `<input type=password>`
    InputPassword,
    /// `<input type=number>`
    InputNumber,
    /// `<input type=checkbox>`
    InputCheckbox,
    /// `<input type=radio>`
    InputRadio,
    /// `<select>`
    Select,
}

impl Tag {
    /// The token string of the observation (MiniWoB style: `input_text`, …).
    pub fn token(self) -> &'static str {
        match self {
            Tag::Div => "div",
            Tag::Nav => "nav",
            Tag::Footer => "footer",
            Tag::H5 => "h5",
            Tag::H6 => "h6",
            Tag::P => "p",
            Tag::Span => "span",
            Tag::A => "a",
            Tag::Label => "label",
            Tag::Button => "button",
            Tag::Img => "img",
            Tag::InputText => "input_text",
            Tag::InputPassword => "input_password",
            Tag::InputNumber => "input_number",
            Tag::InputCheckbox => "input_checkbox",
            Tag::InputRadio => "input_radio",
            Tag::Select => "select",
        }
    }

    /// All tags.
    pub const ALL: [Tag; 17] = [
        Tag::Div,
        Tag::Nav,
        Tag::Footer,
        Tag::H5,
        Tag::H6,
        Tag::P,
        Tag::Span,
        Tag::A,
        Tag::Label,
        Tag::Button,
        Tag::Img,
        Tag::InputText,
        Tag::InputPassword,
        Tag::InputNumber,
        Tag::InputCheckbox,
        Tag::InputRadio,
        Tag::Select,
    ];

    fn html(self) -> &'static str {
        match self {
            Tag::InputText
            | Tag::InputPassword
            | Tag::InputNumber
            | Tag::InputCheckbox
            | Tag::InputRadio => "input",
            other => other.token(),
        }
    }

    fn input_type(self) -> Option<&'static str> {
        match self {
            Tag::InputText => Some("text"),
            Tag::InputPassword => Some("password"),
            Tag::InputNumber => Some("number"),
            Tag::InputCheckbox => Some("checkbox"),
            Tag::InputRadio => Some("radio"),
            _ => None,
        }
    }

    /// Inputs and selects: elements that hold a value and accept the "type" action.
    pub fn is_control(self) -> bool {
        matches!(
            self,
            Tag::InputText
                | Tag::InputPassword
                | Tag::InputNumber
                | Tag::InputCheckbox
                | Tag::InputRadio
                | Tag::Select
        )
    }

    /// Checkbox or radio (their observed value is `true`/`false`).
    pub fn is_toggle(self) -> bool {
        matches!(self, Tag::InputCheckbox | Tag::InputRadio)
    }
}

/// What clicking an element does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Behaviour {
    /// Nothing (no id: not actionable, the DOM does not change).
    Inert,
    /// Actionable (gets the `visited` class); inputs, dead buttons.
    Actionable,
    /// Ends the episode with −1.
    Distractor,
    /// Shows the next page when clicked on page `.0`.
    Next(u16),
    /// Submits the form.
    Submit,
    /// Shows/hides the element with this index (navbar menu).
    Toggle(u32),
}

/// Box model of an element in the imposed layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Block {
    /// Padding 2 px on every side, height = children + 4 px.
    Container,
    /// Fixed height in px.
    Leaf(u16),
}

/// Padding of containers, px.
pub const PAD: f32 = 2.0;
/// Width of the website root, px (gMiniWoB's `#wrap`).
pub const ROOT_WIDTH: f32 = 375.0;

/// One element. Elements are stored in document (pre-)order; the subtree of `i` is `i+1..end`.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// Kind.
    pub tag: Tag,
    /// One past the last descendant.
    pub end: u32,
    /// Own text.
    pub text: String,
    /// `placeholder` attribute.
    pub placeholder: String,
    /// `class` attribute (without `visited`).
    pub classes: String,
    /// `id` attribute (empty for none).
    pub html_id: String,
    /// Click behaviour.
    pub behaviour: Behaviour,
    /// Box model.
    pub block: Block,
    /// Initially hidden (`display: none`).
    pub hidden: bool,
    /// Options of a `<select>` (string ids).
    pub options: Vec<u32>,
    /// `value` attribute of a radio button (string id).
    pub radio_value: u32,
    /// Radio group (the `name` attribute).
    pub group: Option<u32>,
    /// Profile field this element holds, if any.
    pub field: Option<u16>,
    /// Radios: whether A2Perf's lookup finds the group from the id (the concept between the
    /// id's first two `_` names the group's root class); false for `cc` (see [`crate::dom::Quirks`]).
    pub group_from_id: bool,
}

impl Node {
    fn new(tag: Tag, block: Block) -> Self {
        Self {
            tag,
            end: 0,
            text: String::new(),
            placeholder: String::new(),
            classes: String::new(),
            html_id: String::new(),
            behaviour: Behaviour::Inert,
            block,
            hidden: false,
            options: Vec::new(),
            radio_value: 0,
            group: None,
            field: None,
            group_from_id: false,
        }
    }

    /// Whether the element gets the `visited` class when acted on.
    pub fn actionable(&self) -> bool {
        self.behaviour != Behaviour::Inert
    }
}

/// How a profile field is read from the page.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldKind {
    /// Text/number/password input or select: its value string.
    Text,
    /// Checkbox: checked ⇔ value `true`.
    Check,
    /// Radio group: the checked radio's value.
    Radio,
}

/// One profile field (sorted by key).
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// Profile key (the JS concept name).
    pub key: &'static str,
    /// Gold value for this episode.
    pub value: String,
    /// String id of `value`.
    pub value_id: u32,
    /// How it is read.
    pub kind: FieldKind,
    /// Elements holding it (one, or the radios of the group).
    pub nodes: Vec<u32>,
}

/// Tokens of an element's static attributes.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct NodeTokens {
    /// `tag`.
    pub tag: Vec<u32>,
    /// `text`.
    pub text: Vec<u32>,
    /// `placeholder`.
    pub placeholder: Vec<u32>,
    /// `classes` without and with `visited`.
    pub classes: [Vec<u32>; 2],
}

/// A website ready to be played: elements, profile and pre-tokenised strings.
#[derive(Clone, Debug, PartialEq)]
pub struct Website {
    /// The design it was built from.
    pub design: Design,
    /// Elements in document order.
    pub nodes: Vec<Node>,
    /// Element index of each page's root.
    pub pages: Vec<u32>,
    /// Profile fields sorted by key.
    pub fields: Vec<Field>,
    /// Interned value strings; id 0 is `""`, 1 `"true"`, 2 `"false"`.
    pub strings: Vec<String>,
    /// Tokens of `strings`.
    pub string_tokens: Vec<Vec<u32>>,
    /// Tokens of every element.
    pub tokens: Vec<NodeTokens>,
    /// Tokens of profile keys and values.
    pub profile_tokens: Vec<(Vec<u32>, Vec<u32>)>,
    /// Indices of all controls (inputs and selects).
    pub controls: Vec<u32>,
    /// Radio buttons of each radio group (the index is [`Node::group`]).
    pub radio_groups: Vec<Vec<u32>>,
    /// For every element, the element A2Perf's `visitGroup` acts on when given its `id`: the
    /// first (in document order) with the same `id`, except that a page's next/submit button
    /// owns its id; itself when its id is unique or empty.
    pub id_owner: Vec<u32>,
}

/// String id of `"true"`.
pub const TRUE_ID: u32 = 1;
/// String id of `"false"`.
pub const FALSE_ID: u32 = 2;
/// String id of `"1"` (loosely equal to `true` in JavaScript, which A2Perf's checkbox rule uses).
pub const ONE_ID: u32 = 3;

/// The concept A2Perf's `visitGroup` reads from an element id: the text between its first two
/// `_` (`actionable_credit_card_type_p0_i0` → `credit`).
///
/// ```
/// assert_eq!(a2perf_web::site::concept_from_id("actionable_cabin_p1_i0"), "cabin");
/// assert_eq!(a2perf_web::site::concept_from_id("actionable_credit_card_type_p0_i1"), "credit");
/// ```
pub fn concept_from_id(id: &str) -> &str {
    let rest = id.find('_').map_or("", |k| &id[k + 1..]);
    rest.find('_').map_or("", |k| &rest[..k])
}

struct Builder<'a> {
    nodes: Vec<Node>,
    strings: Vec<String>,
    page: usize,
    radio_groups: Vec<Vec<u32>>,
    rng: &'a mut RngStream,
}

impl Builder<'_> {
    fn intern(&mut self, s: &str) -> u32 {
        intern(&mut self.strings, s)
    }

    fn push(&mut self, mut n: Node) -> u32 {
        n.end = self.nodes.len() as u32 + 1;
        self.nodes.push(n);
        self.nodes.len() as u32 - 1
    }

    fn open(&mut self, tag: Tag, classes: &str, id: &str) -> u32 {
        let mut n = Node::new(tag, Block::Container);
        n.classes = classes.into();
        n.html_id = id.into();
        self.push(n)
    }

    fn close(&mut self, i: u32) {
        self.nodes[i as usize].end = self.nodes.len() as u32;
    }

    fn leaf(&mut self, tag: Tag, text: &str, classes: &str, id: &str, b: Behaviour) -> u32 {
        let h = if tag == Tag::Img { 40 } else { 20 };
        let mut n = Node::new(tag, Block::Leaf(h));
        n.text = text.into();
        n.classes = classes.into();
        n.html_id = id.into();
        n.behaviour = b;
        self.push(n)
    }

    fn input(&mut self, tag: Tag, placeholder: &str, classes: &str, id: &str) -> u32 {
        let mut n = Node::new(tag, Block::Leaf(20));
        n.placeholder = placeholder.into();
        n.classes = classes.into();
        n.html_id = id.into();
        n.behaviour = Behaviour::Actionable;
        self.push(n)
    }

    fn text_input(&mut self, concept: &str, label: Option<&str>, tag: Tag, ph: &str) -> u32 {
        let g = self.open(Tag::Div, "form-group", &format!("group_{concept}"));
        if let Some(l) = label {
            self.leaf(
                Tag::Label,
                l,
                "",
                &format!("label_{concept}"),
                Behaviour::Inert,
            );
        }
        let i = self.input(tag, ph, "form-control", &format!("actionable_{concept}"));
        self.close(g);
        i
    }

    fn checkbox(&mut self, concept: &str, label: &str) -> u32 {
        let g = self.open(
            Tag::Div,
            "custom-control custom-checkbox",
            &format!("group_{concept}"),
        );
        let i = self.input(
            Tag::InputCheckbox,
            "",
            "custom-control-input",
            &format!("actionable_{concept}"),
        );
        self.leaf(
            Tag::Label,
            label,
            "custom-control-label",
            "",
            Behaviour::Inert,
        );
        self.close(g);
        i
    }

    fn radios(&mut self, concept: &str, header: &str, options: &[&str]) -> Vec<u32> {
        let p = self.page;
        let outer = self.open(Tag::Div, "d-block my-3", "");
        if !header.is_empty() {
            self.leaf(Tag::H6, header, "mb-3", "", Behaviour::Inert);
        }
        // The group's root class is `{concept}root`, as in the original, whose lookup parsed the
        // concept from the radio's id and so broke on concepts containing `_`
        // (`credit_card_type` → `credit`); `group_from_id` records whether that lookup succeeds.
        let inner = self.open(Tag::Div, &format!("d-block my-3 {concept}root"), "");
        let group = self.radio_groups.len() as u32;
        self.radio_groups.push(Vec::new());
        let mut out = Vec::new();
        for (k, opt) in options.iter().enumerate() {
            let w = self.open(
                Tag::Div,
                "custom-control custom-radio",
                &format!("group_{concept}_p{p}_i{k}"),
            );
            let i = self.input(
                Tag::InputRadio,
                "",
                "custom-control-input",
                &format!("actionable_{concept}_p{p}_i{k}"),
            );
            let v = self.intern(opt);
            let node = &mut self.nodes[i as usize];
            node.radio_value = v;
            node.group = Some(group);
            node.group_from_id = concept_from_id(&node.html_id) == concept;
            self.radio_groups[group as usize].push(i);
            self.leaf(
                Tag::Label,
                opt,
                "custom-control-label",
                "",
                Behaviour::Inert,
            );
            self.close(w);
            out.push(i);
        }
        self.close(inner);
        self.close(outer);
        out
    }

    fn button(&mut self, concept: &str, text: &str, classes: &str, b: Behaviour) -> u32 {
        let p = self.page;
        let g = self.open(Tag::Div, "", &format!("group_{concept}_p{p}"));
        let i = self.leaf(
            Tag::Button,
            text,
            classes,
            &format!("actionable_{concept}_p{p}"),
            b,
        );
        self.close(g);
        i
    }

    fn link(&mut self, concept: &str, text: &str) {
        let p = self.page;
        let g = self.open(Tag::Div, "", &format!("group_{concept}_p{p}"));
        self.leaf(
            Tag::A,
            text,
            "",
            &format!("actionable_{concept}_p{p}"),
            Behaviour::Distractor,
        );
        self.close(g);
    }

    fn price(&mut self) -> String {
        format!("${}", 1 + self.rng.below(50))
    }

    /// Renders a primitive; returns the elements of its profile field (none for a passive one).
    fn primitive(&mut self, prim: Primitive) -> Vec<u32> {
        let c = prim.info().concept;
        let one = |i: u32| vec![i];
        match prim.name() {
            "addressline1" => one(self.text_input(c, Some("Address"), Tag::InputText, "")),
            "addressline2" => one(self.text_input(c, None, Tag::InputText, "Apt #")),
            "captcha" => one(self.text_input(c, Some("Enter Captcha"), Tag::InputText, "")),
            "cccvv" => one(self.text_input(c, Some("CVV"), Tag::InputText, "")),
            "ccexpdate" => one(self.text_input(c, Some("Expiration date"), Tag::InputText, "")),
            "ccnumber" => one(self.text_input(c, Some("Credit card number"), Tag::InputText, "")),
            "city" => one(self.text_input(c, Some("City"), Tag::InputText, "")),
            "departureairport" => one(self.text_input(c, Some("From"), Tag::InputText, "")),
            "departuredate" => one(self.text_input(c, Some("Depart"), Tag::InputText, "")),
            "destinationairport" => one(self.text_input(c, Some("To"), Tag::InputText, "")),
            "destinationdate" => one(self.text_input(c, Some("Return"), Tag::InputText, "")),
            "firstname" => one(self.text_input(c, Some("First Name"), Tag::InputText, "")),
            "fullname" => one(self.text_input(c, Some("Full Name"), Tag::InputText, "")),
            "lastname" => one(self.text_input(c, Some("Last Name"), Tag::InputText, "")),
            "zipcode" => one(self.text_input(c, Some("ZIP Code"), Tag::InputText, "")),
            "username" => one(self.text_input(c, None, Tag::InputText, "Username")),
            "password" => one(self.text_input(c, None, Tag::InputPassword, "Password")),
            "numberofpeople" => {
                one(self.text_input(c, Some("Number of passengers"), Tag::InputNumber, ""))
            }
            "rememberme" => one(self.checkbox(c, "Remember me")),
            "stayloggedin" => one(self.checkbox(c, "Stay logged in")),
            "cabin" => self.radios(c, "Cabin", &["Economy", "First"]),
            "cc" => self.radios(c, "Payment", &["Credit Card", "Debit Card"]),
            "flighttype" => self.radios(c, "", &["Oneway", "Roundtrip"]),
            "state" => vec![self.state_select()],
            _ => {
                self.passive(prim);
                vec![]
            }
        }
    }

    /// Renders a passive primitive (one that holds no profile field).
    fn passive(&mut self, prim: Primitive) {
        let c = prim.info().concept;
        match prim.name() {
            "inpgroup1" => self.input_group(),
            "forgotpassowrd" => self.link(c, "Forgot password."),
            "forgotusername" => self.link(c, "Forgot user name."),
            "header" => self.header("Shipping Information"),
            "header_login" => self.header("Login"),
            "header_select_items" => self.header("Select items"),
            "navbar" => self.navbar(),
            "carousel" => self.carousel(),
            "cart" => self.cart(),
            "dealmedia" => self.deal_media(),
            "deck" => self.deck(),
            "footer1" => self.footer(),
            // next_* and submit are placed by `page`.
            _ => {}
        }
    }

    /// The `state` select (CA/NY); returns the select.
    fn state_select(&mut self) -> u32 {
        let g = self.open(Tag::Div, "form-group", "group_state");
        let mut n = Node::new(Tag::Select, Block::Leaf(20));
        n.classes = "custom-select d-block w-100".into();
        n.html_id = "actionable_state".into();
        n.behaviour = Behaviour::Actionable;
        n.options = vec![self.intern("CA"), self.intern("NY")];
        let i = self.push(n);
        self.close(g);
        i
    }

    /// A search input group (`inpgroup1`; holds no field).
    fn input_group(&mut self) {
        let p = self.page;
        let g = self.open(Tag::Div, "input-group", &format!("group_inputgroup_p{p}"));
        self.input(
            Tag::InputText,
            "Search",
            "form-control",
            &format!("actionable_inputgroup_p{p}"),
        );
        self.close(g);
    }

    /// The navbar: a brand link and five menu links (distractors), and a toggler that shows the menu.
    fn navbar(&mut self) {
        let p = self.page;
        let d = Behaviour::Distractor;
        let nav = self.open(
            Tag::Nav,
            "navbar navbar-dark bg-dark",
            &format!("group_navbar_p{p}"),
        );
        self.leaf(
            Tag::A,
            "GShopping",
            "navbar-brand",
            &format!("actionable_navbar_p{p}_brand"),
            d,
        );
        let t = self.leaf(
            Tag::Button,
            "Menu",
            "navbar-toggler",
            &format!("actionable_navbar_p{p}_toggler"),
            Behaviour::Inert,
        );
        let menu = self.open(Tag::Div, "collapse navbar-collapse", "");
        self.nodes[menu as usize].hidden = true;
        self.nodes[t as usize].behaviour = Behaviour::Toggle(menu);
        for (k, item) in ["Home", "Login", "Account", "Cart", "Checkout"]
            .iter()
            .enumerate()
        {
            self.leaf(
                Tag::A,
                item,
                "nav-link",
                &format!("actionable_navbar_p{p}_i{k}"),
                d,
            );
        }
        self.close(menu);
        self.close(nav);
    }

    /// A five-slide carousel showing a random slide, with previous/next links (all distractors).
    fn carousel(&mut self) {
        let p = self.page;
        let d = Behaviour::Distractor;
        let active = self.rng.index(5);
        let g = self.open(Tag::Div, "carousel slide", &format!("group_carousel_p{p}"));
        let inner = self.open(Tag::Div, "carousel-inner", "");
        for k in 0..5 {
            let cls = if k == active {
                "carousel-item active"
            } else {
                "carousel-item"
            };
            let i = self.leaf(
                Tag::Img,
                "",
                cls,
                &format!("actionable_carousel_p{p}_i{k}"),
                d,
            );
            self.nodes[i as usize].hidden = k != active;
        }
        self.close(inner);
        self.leaf(
            Tag::A,
            "Previous",
            "carousel-control-prev",
            &format!("actionable_carousel_p{p}_i5"),
            d,
        );
        self.leaf(
            Tag::A,
            "Next",
            "carousel-control-next",
            &format!("actionable_carousel_p{p}_i6"),
            d,
        );
        self.close(g);
    }

    /// A cart of three items with random prices, remove links and a promo-code input group.
    fn cart(&mut self) {
        let p = self.page;
        let d = Behaviour::Distractor;
        let g = self.open(Tag::Div, "card", &format!("group_cart_p{p}"));
        self.leaf(Tag::H5, "Your cart", "card-header", "", Behaviour::Inert);
        for (k, item) in ["Shoe", "Bag", "Tshirt"].iter().enumerate() {
            let row = self.open(Tag::Div, "list-group-item", "");
            self.leaf(Tag::Span, item, "", "", Behaviour::Inert);
            let price = self.price();
            self.leaf(Tag::Span, &price, "text-muted", "", Behaviour::Inert);
            self.leaf(
                Tag::A,
                "Remove",
                "remove",
                &format!("actionable_cart_p{p}_i{k}"),
                d,
            );
            self.close(row);
        }
        let ig = self.open(Tag::Div, "input-group", "");
        self.input(
            Tag::InputText,
            "Promo code",
            "form-control",
            &format!("actionable_cart_p{p}_promo"),
        );
        self.leaf(
            Tag::Button,
            "Redeem",
            "btn btn-secondary",
            &format!("actionable_cart_p{p}_redeem"),
            d,
        );
        self.close(ig);
        self.close(g);
    }

    /// The "Deal of the Day" media object.
    fn deal_media(&mut self) {
        let p = self.page;
        let d = Behaviour::Distractor;
        let g = self.open(Tag::Div, "media", &format!("group_dealmedia_p{p}"));
        self.leaf(Tag::Img, "", "mr-3", "", Behaviour::Inert);
        let body = self.open(Tag::Div, "media-body", "");
        self.leaf(Tag::H5, "Deal of the Day", "mt-0", "", Behaviour::Inert);
        self.leaf(Tag::P, "Gaming workstation", "", "", Behaviour::Inert);
        self.leaf(
            Tag::A,
            "Get it today!",
            "",
            &format!("actionable_dealmedia_p{p}"),
            d,
        );
        self.close(body);
        self.close(g);
    }

    /// A deck of four cards with random prices and star ratings.
    fn deck(&mut self) {
        let p = self.page;
        let d = Behaviour::Distractor;
        let g = self.open(Tag::Div, "card-deck", &format!("group_deck_p{p}"));
        for k in 0..4 {
            let card = self.open(Tag::Div, "card", "");
            self.leaf(
                Tag::Img,
                "",
                "card-img-top",
                &format!("actionable_deck_p{p}_img{k}"),
                d,
            );
            self.leaf(
                Tag::A,
                &format!("Title {}", k + 1),
                "card-title",
                &format!("actionable_deck_p{p}_i{k}"),
                d,
            );
            let price = self.price();
            self.leaf(Tag::P, &price, "card-text", "", Behaviour::Inert);
            let stars = format!("{} stars", 1 + self.rng.below(5));
            self.leaf(Tag::P, &stars, "text-muted", "", Behaviour::Inert);
            self.close(card);
        }
        self.close(g);
    }

    /// The footer with four links.
    fn footer(&mut self) {
        let p = self.page;
        let d = Behaviour::Distractor;
        let g = self.open(Tag::Footer, "footer", &format!("group_footer_p{p}"));
        self.leaf(Tag::P, "2020-2021 The Company.", "", "", Behaviour::Inert);
        for (k, l) in ["Contact", "Terms", "Support", "Full Site"]
            .iter()
            .enumerate()
        {
            self.leaf(
                Tag::A,
                l,
                "footer-link",
                &format!("actionable_footer_p{p}_i{k}"),
                d,
            );
        }
        self.close(g);
    }

    fn header(&mut self, text: &str) {
        self.leaf(Tag::H5, text, "mb-3", "group_header", Behaviour::Inert);
    }
}

impl Builder<'_> {
    /// Renders page `p` (the last one when `last`) with its primitives `list`: the primitives
    /// outside the form, then the form with the others and the page's next/submit button.
    /// Active primitives join `placed`; returns the page's root element.
    fn page(
        &mut self,
        p: usize,
        last: bool,
        list: &[Primitive],
        placed: &mut Vec<(Primitive, Vec<u32>)>,
    ) -> u32 {
        self.page = p;
        let page = self.open(Tag::Div, "page", &format!("page{p}"));
        self.nodes[page as usize].hidden = p > 0;
        for &prim in list.iter().filter(|q| !q.in_form()) {
            self.primitive(prim);
        }
        let form = self.open(Tag::Div, "container", &format!("mainform_p{p}"));
        let nav = if last {
            list.iter().position(|q| q.name() == "submit")
        } else {
            list.iter().position(|q| is_next(*q))
        };
        for (k, &prim) in list.iter().enumerate().filter(|(_, q)| q.in_form()) {
            if Some(k) == nav {
                continue;
            }
            if is_next(prim) || prim.name() == "submit" {
                let concept = prim.info().concept;
                self.button(
                    concept,
                    button_text(prim),
                    "btn btn-secondary btn-sm btn-block",
                    Behaviour::Actionable,
                );
                continue;
            }
            let nodes = self.primitive(prim);
            if prim.info().active {
                self.place(prim, nodes, placed);
            }
        }
        let (concept, text, beh) = match (last, nav) {
            (true, Some(k)) => ("submit", button_text(list[k]), Behaviour::Submit),
            (true, None) => ("submit", "Submit", Behaviour::Submit),
            (false, Some(k)) => ("next", button_text(list[k]), Behaviour::Next(p as u16)),
            (false, None) => ("next", "Next", Behaviour::Next(p as u16)),
        };
        let cls = if last {
            "btn btn-primary btn-lg btn-block"
        } else {
            "btn btn-secondary btn-sm btn-block"
        };
        self.button(concept, text, cls, beh);
        self.close(form);
        self.close(page);
        page
    }

    /// Records the field elements `nodes` of active primitive `prim` in `placed`.
    fn place(&self, prim: Primitive, nodes: Vec<u32>, placed: &mut Vec<(Primitive, Vec<u32>)>) {
        match placed.iter_mut().find(|(q, _)| *q == prim) {
            // A later page's copy: a radio group (ids with the page) joins the field; another
            // control shares the first copy's id and holds nothing.
            Some((_, first)) => {
                if nodes
                    .first()
                    .is_some_and(|&n| self.nodes[n as usize].tag == Tag::InputRadio)
                {
                    first.extend(nodes);
                }
            }
            None => placed.push((prim, nodes)),
        }
    }

    /// The profile: one field per placed active primitive, sorted by key, with this episode's
    /// value; marks the field on its elements.
    fn profile(&mut self, mut placed: Vec<(Primitive, Vec<u32>)>) -> Vec<Field> {
        placed.sort_by_key(|(p, _)| p.info().concept);
        let mut fields = Vec::with_capacity(placed.len());
        for (k, (prim, nodes)) in placed.into_iter().enumerate() {
            let info = prim.info();
            let value = info
                .value
                .map(|v| draw_value(v, self.rng))
                .unwrap_or_default();
            let value_id = self.intern(value);
            let kind = match self.nodes[nodes[0] as usize].tag {
                Tag::InputCheckbox => FieldKind::Check,
                Tag::InputRadio => FieldKind::Radio,
                _ => FieldKind::Text,
            };
            for &n in &nodes {
                self.nodes[n as usize].field = Some(k as u16);
            }
            fields.push(Field {
                key: info.concept,
                value: value.to_string(),
                value_id,
                kind,
                nodes,
            });
        }
        fields
    }
}

/// The primitives page `prims` renders: each once, and without an active primitive already
/// `placed` on an earlier page (unless `quirks.duplicate_fields`).
fn page_primitives(
    prims: &[Primitive],
    placed: &[(Primitive, Vec<u32>)],
    quirks: Quirks,
) -> Vec<Primitive> {
    let mut list: Vec<Primitive> = Vec::new();
    for (k, &prim) in prims.iter().enumerate() {
        if prims[..k].contains(&prim) {
            continue;
        }
        if prim.info().active && !quirks.duplicate_fields && placed.iter().any(|(q, _)| *q == prim)
        {
            continue;
        }
        list.push(prim);
    }
    list
}

/// Tokens of every element's static attributes.
fn node_tokens(nodes: &[Node], vocab: &Vocabulary) -> Vec<NodeTokens> {
    nodes
        .iter()
        .map(|n| {
            let cls = if n.classes.is_empty() {
                "no_class".to_string()
            } else {
                n.classes.clone()
            };
            NodeTokens {
                tag: vocab.encode(n.tag.token()),
                text: vocab.encode(&n.text),
                placeholder: vocab.encode(&n.placeholder),
                classes: [
                    vocab.encode(&cls),
                    vocab.encode(&format!("{} visited", n.classes)),
                ],
            }
        })
        .collect()
}

/// [`Website::id_owner`]: for every element, the element that owns its `id`.
fn id_owners(nodes: &[Node]) -> Vec<u32> {
    // A page's extra `next_*` (or `submit`) buttons share the working button's id; the
    // original bound the transition to the first element with that id and `visitGroup`
    // acts on the first, so any of them works: the working button owns the id.
    let mut first_with: HashMap<&str, u32> = nodes
        .iter()
        .enumerate()
        .filter(|(_, n)| matches!(n.behaviour, Behaviour::Next(_) | Behaviour::Submit))
        .map(|(i, n)| (n.html_id.as_str(), i as u32))
        .collect();
    nodes
        .iter()
        .enumerate()
        .map(|(i, n)| {
            if n.html_id.is_empty() {
                i as u32
            } else {
                *first_with.entry(n.html_id.as_str()).or_insert(i as u32)
            }
        })
        .collect()
}

fn button_text(prim: Primitive) -> &'static str {
    match prim.name() {
        "next_checkout" => "Checkout",
        "next_login" => "Login and Checkout",
        "next_login_page" => "Login",
        _ => "Place Order",
    }
}

fn is_next(prim: Primitive) -> bool {
    prim.name().starts_with("next_")
}

/// Interns `s` into `strings`, returning its id.
pub fn intern(strings: &mut Vec<String>, s: &str) -> u32 {
    if let Some(i) = strings.iter().position(|x| x == s) {
        return i as u32;
    }
    strings.push(s.to_string());
    strings.len() as u32 - 1
}

fn draw_value(v: ProfileValue, rng: &mut RngStream) -> &'static str {
    match v {
        ProfileValue::Fixed(s) => s,
        ProfileValue::OneOf(c) => c[rng.index(c.len())],
    }
}

impl Website {
    /// Builds the website of `design` with this episode's random content (profile values, prices,
    /// carousel slide) drawn from `rng`.
    ///
    /// Rules where the original was ambiguous or broken: a second instance of an active concept on
    /// a later page is not rendered (the original gave an input copy the first copy's id, so
    /// only the first was usable; [`Website::build_with`] renders it on request); repeated
    /// (primitive, page) pairs are rendered once (as `design_environment` does); on each page but
    /// the last, the first `next_*` button is the page's "next" control (default text "Next")
    /// and any other is a dead button; on the last page the first `submit` is the submit control
    /// (default "Submit") and other buttons are dead.
    ///
    /// ```
    /// use a2perf_core::RngStream;
    /// use a2perf_web::{Design, Primitive, Website, Vocabulary};
    /// let p = |n| Primitive::from_name(n).unwrap();
    /// let d = Design { pages: vec![vec![p("username"), p("cc")], vec![p("rememberme")]] };
    /// let site = Website::build(&d, &mut RngStream::new(0, "doc"), Vocabulary::standard());
    /// assert_eq!(site.fields.len(), 3);
    /// assert_eq!(site.pages.len(), 2);
    /// assert!(site.to_html(false).contains("Payment"));
    /// ```
    pub fn build(design: &Design, rng: &mut RngStream, vocab: &Vocabulary) -> Website {
        Self::build_with(design, rng, vocab, Quirks::default())
    }

    /// [`Website::build`] with the original's page behaviours that `quirks` asks for (of which
    /// [`Quirks::duplicate_fields`] changes the elements; the random content is the same).
    pub fn build_with(
        design: &Design,
        rng: &mut RngStream,
        vocab: &Vocabulary,
        quirks: Quirks,
    ) -> Website {
        let mut b = Builder {
            nodes: Vec::new(),
            strings: vec![String::new(), "true".into(), "false".into(), "1".into()],
            page: 0,
            radio_groups: Vec::new(),
            rng,
        };
        let mut placed: Vec<(Primitive, Vec<u32>)> = Vec::new();
        let n_pages = design.pages.len().max(1);
        let mut pages = Vec::with_capacity(n_pages);
        for p in 0..n_pages {
            let prims = design.pages.get(p).map_or(&[][..], Vec::as_slice);
            let list = page_primitives(prims, &placed, quirks);
            pages.push(b.page(p, p + 1 == n_pages, &list, &mut placed));
        }
        let fields = b.profile(placed);
        let Builder {
            nodes,
            strings,
            radio_groups,
            ..
        } = b;
        Website {
            design: design.clone(),
            string_tokens: strings.iter().map(|s| vocab.encode(s)).collect(),
            tokens: node_tokens(&nodes, vocab),
            profile_tokens: fields
                .iter()
                .map(|f| (vocab.encode(f.key), vocab.encode(&f.value)))
                .collect(),
            controls: nodes
                .iter()
                .enumerate()
                .filter(|(_, n)| n.tag.is_control())
                .map(|(i, _)| i as u32)
                .collect(),
            id_owner: id_owners(&nodes),
            nodes,
            pages,
            fields,
            strings,
            radio_groups,
        }
    }

    /// Radio buttons of group `g` (empty for an unknown group).
    pub fn radio_group(&self, g: u32) -> &[u32] {
        self.radio_groups.get(g as usize).map_or(&[], Vec::as_slice)
    }

    /// Initial value string id of element `i` (selects show their first option).
    pub fn initial_value(&self, i: usize) -> u32 {
        let n = &self.nodes[i];
        match n.tag {
            Tag::Select => n.options.first().copied().unwrap_or(0),
            _ => 0,
        }
    }

    /// Number of elements on each page (hidden ones included).
    pub fn page_sizes(&self) -> Vec<usize> {
        self.pages
            .iter()
            .map(|&p| (self.nodes[p as usize].end - p) as usize)
            .collect()
    }

    /// The page as a standalone HTML document. With `show_all`, every page is visible at once
    /// (for people looking at a design); otherwise only the first, as the agent sees it.
    pub fn to_html(&self, show_all: bool) -> String {
        shell_html(&self.profile_text(), &self.root_html(show_all))
    }

    /// The profile as shown above the form (`key: value | …`).
    pub fn profile_text(&self) -> String {
        let profile: Vec<String> = self
            .fields
            .iter()
            .map(|f| format!("{}: {}", f.key, f.value))
            .collect();
        profile.join(" | ")
    }

    /// The elements of the website (the content of `#a2p-root`).
    pub fn root_html(&self, show_all: bool) -> String {
        self.elements_html(show_all, None)
    }

    /// The page as it stands in `state`, as a standalone HTML document (what the web
    /// environment's `"html"` render mode returns): [`to_html`](Self::to_html)`(false)` with
    /// the state's dynamic part written into the elements — which are displayed (the current
    /// page, opened menus), the `visited` class, `checked` toggles, the `value` of text inputs,
    /// the `selected` option of selects and `autofocus` on the focused element.
    ///
    /// The page is what is displayed, so that both backends render the same state the same:
    /// an element's own `display: none` follows `state.visible` where its parent is displayed
    /// (Chromium reports what is displayed, not the flags), and inside a part that is not
    /// displayed elements keep their initial flag and show `visited` only if they are controls
    /// (whose state the browser always reports). A state of another website (too short) renders
    /// the missing part as initially.
    ///
    /// ```
    /// use a2perf_core::RngStream;
    /// use a2perf_web::site::Tag;
    /// use a2perf_web::{ActionKind, Design, DomState, Primitive, Quirks, Vocabulary, Website};
    /// let p = |n| Primitive::from_name(n).unwrap();
    /// let d = Design { pages: vec![vec![p("username"), p("rememberme")]] };
    /// let site = Website::build(&d, &mut RngStream::new(0, "doc"), Vocabulary::standard());
    /// let mut state = DomState::default();
    /// state.reset(&site);
    /// assert_eq!(site.state_html(&state), site.to_html(false));
    /// let check = site.nodes.iter().position(|n| n.tag == Tag::InputCheckbox).unwrap();
    /// state.apply(&site, check, ActionKind::Click, Quirks::default());
    /// let html = site.state_html(&state);
    /// assert!(html.contains(" checked") && html.contains(" autofocus"));
    /// ```
    pub fn state_html(&self, state: &DomState) -> String {
        shell_html(
            &self.profile_text(),
            &self.elements_html(false, Some(state)),
        )
    }

    fn elements_html(&self, show_all: bool, state: Option<&DomState>) -> String {
        let mut h = String::with_capacity(self.nodes.len() * 160);
        let mut stack: Vec<u32> = Vec::new();
        for (i, n) in self.nodes.iter().enumerate() {
            while let Some(&top) = stack.last() {
                if self.nodes[top as usize].end as usize <= i {
                    let _ = write!(h, "</{}>", self.nodes[top as usize].tag.html());
                    stack.pop();
                } else {
                    break;
                }
            }
            let dynamic = state.map(|st| ElementState::of(st, i, stack.last(), n));
            self.open_tag(&mut h, i, show_all, dynamic.as_ref());
            match n.block {
                Block::Container => stack.push(i as u32),
                Block::Leaf(_) => {
                    if n.tag == Tag::Select {
                        // The first option is selected by default; another chosen is marked.
                        let chosen = dynamic.as_ref().map(|d| d.value);
                        let mut selected = n.options.first().copied() == chosen;
                        for &o in &n.options {
                            if !selected && chosen == Some(o) {
                                selected = true;
                                h.push_str("<option selected>");
                            } else {
                                h.push_str("<option>");
                            }
                            escape_into(&mut h, &self.strings[o as usize]);
                            h.push_str("</option>");
                        }
                        h.push_str("</select>");
                    } else if n.tag != Tag::Img && !n.tag.html().eq("input") {
                        escape_into(&mut h, &n.text);
                        let _ = write!(h, "</{}>", n.tag.html());
                    }
                }
            }
            h.push('\n');
        }
        while let Some(top) = stack.pop() {
            let _ = write!(h, "</{}>", self.nodes[top as usize].tag.html());
        }
        h
    }

    fn open_tag(&self, h: &mut String, i: usize, show_all: bool, state: Option<&ElementState>) {
        let n = &self.nodes[i];
        let b = match n.block {
            Block::Container => "c".to_string(),
            Block::Leaf(px) => format!("l{px}"),
        };
        let _ = write!(h, "<{} data-n=\"{i}\" data-b=\"{b}\"", n.tag.html());
        if let Some(t) = n.tag.input_type() {
            let _ = write!(h, " type=\"{t}\"");
        }
        if !n.html_id.is_empty() {
            h.push_str(" id=\"");
            escape_into(h, &n.html_id);
            h.push('"');
        }
        let hidden = match state {
            Some(st) => st.hidden,
            None => n.hidden && !(show_all && self.pages.contains(&(i as u32))),
        };
        let visited = state.is_some_and(|st| st.visited);
        if !n.classes.is_empty() || hidden || visited {
            h.push_str(" class=\"");
            escape_into(h, &n.classes);
            for (on, class) in [(visited, "visited"), (hidden, "a2p-hidden")] {
                if on {
                    if !h.ends_with('"') {
                        h.push(' ');
                    }
                    h.push_str(class);
                }
            }
            h.push('"');
        }
        if !n.placeholder.is_empty() {
            h.push_str(" placeholder=\"");
            escape_into(h, &n.placeholder);
            h.push('"');
        }
        if let Some(g) = n.group {
            // Copies of a field's radio group share one name, as in the original.
            match n.field {
                Some(f) => {
                    let _ = write!(h, " name=\"field{f}\" value=\"");
                }
                None => {
                    let _ = write!(h, " name=\"radio{g}\" value=\"");
                }
            }
            escape_into(h, &self.strings[n.radio_value as usize]);
            h.push('"');
        }
        if n.actionable() {
            h.push_str(" data-act=\"1\"");
        }
        match n.behaviour {
            Behaviour::Distractor => h.push_str(" data-role=\"distractor\""),
            Behaviour::Submit => h.push_str(" data-role=\"submit\""),
            Behaviour::Next(p) => {
                let _ = write!(h, " data-role=\"next\" data-page=\"{p}\"");
            }
            Behaviour::Toggle(t) => {
                let _ = write!(h, " data-role=\"toggle\" data-target=\"{t}\"");
            }
            Behaviour::Inert | Behaviour::Actionable => {}
        }
        if let Some(st) = state {
            if n.tag.is_toggle() {
                if st.checked {
                    h.push_str(" checked");
                }
            } else if n.tag.is_control() && n.tag != Tag::Select && st.value != 0 {
                h.push_str(" value=\"");
                escape_into(
                    h,
                    self.strings
                        .get(st.value as usize)
                        .map_or("", String::as_str),
                );
                h.push('"');
            }
            if st.focused {
                h.push_str(" autofocus");
            }
        }
        if n.tag == Tag::Img {
            h.push_str(" alt=\"\" src=\"data:image/svg+xml,%3Csvg xmlns='http://www.w3.org/2000/svg' width='8' height='8'%3E%3Crect width='8' height='8' fill='%23bbb'/%3E%3C/svg%3E\"");
        }
        h.push('>');
    }
}

/// The dynamic part of one element in a [`DomState`], as [`Website::state_html`] writes it.
struct ElementState {
    hidden: bool,
    visited: bool,
    checked: bool,
    value: u32,
    focused: bool,
}

impl ElementState {
    /// Element `i` (node `n`, parent element `parent`) in `st`; what `st` lacks is initial.
    fn of(st: &DomState, i: usize, parent: Option<&u32>, n: &Node) -> Self {
        let shown = |j: usize| st.visible.get(j) == Some(&true);
        let parent_shown = parent.is_none_or(|&p| shown(p as usize));
        Self {
            hidden: match st.visible.get(i) {
                Some(&visible) if parent_shown => !visible,
                _ => n.hidden,
            },
            visited: st.visited.get(i) == Some(&true) && (shown(i) || n.tag.is_control()),
            checked: st.checked.get(i).copied().unwrap_or(false),
            value: st.value.get(i).copied().unwrap_or(0),
            focused: st.focused == Some(i as u32),
        }
    }
}

/// A complete HTML document around `root` (the website's elements) with the stylesheet and
/// page script; an empty `root` gives the shell the Chromium backend loads once.
pub fn shell_html(profile: &str, root: &str) -> String {
    let mut h = String::with_capacity(8 * 1024 + root.len());
    h.push_str("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>A2Perf web navigation</title>\n<style>\n");
    h.push_str(STYLE);
    h.push_str("</style></head><body>\n<div id=\"query\">");
    escape_into(&mut h, profile);
    h.push_str("</div>\n<div id=\"a2p-root\">\n");
    h.push_str(root);
    h.push_str("\n</div>\n<script>\n");
    h.push_str(SCRIPT);
    h.push_str("</script>\n</body></html>\n");
    h
}

fn escape_into(h: &mut String, s: &str) {
    for c in s.chars() {
        match c {
            '&' => h.push_str("&amp;"),
            '<' => h.push_str("&lt;"),
            '>' => h.push_str("&gt;"),
            '"' => h.push_str("&quot;"),
            '\'' => h.push_str("&#39;"),
            c => h.push(c),
        }
    }
}

/// The stylesheet that makes every box's geometry independent of fonts.
pub const STYLE: &str = r#"html, body { margin: 0; padding: 0; background: #fff; }
#query { font: 12px monospace; padding: 4px; background: #eef; width: 367px; }
#a2p-root { position: relative; width: 375px; margin: 0; padding: 0; }
#a2p-root * { display: block; box-sizing: border-box; margin: 0; padding: 0; border: 0;
  width: 100%; min-width: 0; min-height: 0; overflow: hidden; white-space: nowrap;
  font: 12px/20px sans-serif; outline: none; }
#a2p-root [data-b="c"] { padding: 2px; background: rgba(0,0,0,0.02); }
#a2p-root [data-b="l20"] { height: 20px; }
#a2p-root [data-b="l40"] { height: 40px; }
#a2p-root input, #a2p-root select { background: #f4f4ff; }
#a2p-root input[type="checkbox"], #a2p-root input[type="radio"] { -webkit-appearance: none; appearance: none; background: #dde; }
#a2p-root input[type="checkbox"]:checked, #a2p-root input[type="radio"]:checked { background: #36c; }
#a2p-root button { background: #ddd; text-align: center; }
#a2p-root .visited { box-shadow: inset 0 0 0 1px #c90; }
#a2p-root .a2p-hidden { display: none !important; }
"#;

/// The page's behaviour and the one-call step/state API used by the Chromium backend.
pub const SCRIPT: &str = r#"(function () {
  'use strict';
  // (Re)initialises the page API over the current content of #a2p-root.
  function init() {
  var root = document.getElementById('a2p-root');
  var nodes = Array.prototype.slice.call(root.querySelectorAll('[data-n]'));
  var pages = nodes.filter(function (e) { return e.classList.contains('page'); });
  var controls = [];
  nodes.forEach(function (e, i) { if (e.tagName === 'INPUT' || e.tagName === 'SELECT') controls.push(i); });
  var a2p = { page: 0, event: 'none' };
  function show(el, on) { if (on) el.classList.remove('a2p-hidden'); else el.classList.add('a2p-hidden'); }
  function visible(el) { var b = el.getBoundingClientRect(); return b.width > 0 || b.height > 0; }
  function mark(el) { if (el.dataset.act) el.classList.add('visited'); }
  function onClick(ev) {
    var el = ev.currentTarget, role = el.dataset.role;
    if (role === 'distractor') { if (a2p.event === 'none') a2p.event = 'distractor'; }
    else if (role === 'submit') { if (a2p.event === 'none') a2p.event = 'submit'; }
    else if (role === 'next') {
      var p = +el.dataset.page;
      if (p === a2p.page && p + 1 < pages.length) {
        var ae = document.activeElement;
        if (ae && ae !== document.body && ae.blur) ae.blur();
        show(pages[p], false); show(pages[p + 1], true); a2p.page = p + 1;
      }
    } else if (role === 'toggle') {
      var t = nodes[+el.dataset.target];
      show(t, t.classList.contains('a2p-hidden'));
    }
  }
  nodes.forEach(function (e) { if (e.dataset.role) e.addEventListener('click', onClick); });
  a2p.state = function () {
    var rb = root.getBoundingClientRect(), v = [], c = [], x = [], w = [];
    for (var i = 0; i < nodes.length; i++) {
      var b = nodes[i].getBoundingClientRect();
      if (b.width > 0 || b.height > 0) {
        v.push(i, b.left - rb.left, b.top - rb.top, b.width, b.height);
        c.push(nodes[i].className);
      }
    }
    controls.forEach(function (i) {
      var e = nodes[i];
      x.push(e.type === 'checkbox' || e.type === 'radio' ? (e.checked ? 'true' : 'false') : e.value);
      w.push(e.classList.contains('visited') ? 1 : 0);
    });
    var ae = document.activeElement, f = -1;
    if (ae && ae.dataset && ae.dataset.n !== undefined) f = +ae.dataset.n;
    return { v: v, c: c, x: x, w: w, f: f, p: a2p.page, e: a2p.event };
  };
  // The radios of el's group (under its root, two levels up); null when A2Perf's lookup (the
  // concept between the id's first two '_' names the root's class) fails and ccBug asks for it.
  function groupOf(el, ccBug) {
    var root = el.parentElement && el.parentElement.parentElement;
    if (ccBug) {
      var c = el.id.substring(el.id.indexOf('_') + 1);
      c = c.substring(0, c.indexOf('_'));
      root = c ? el.closest('.' + c + 'root') : null;
    }
    return root ? root.querySelectorAll('input[type="radio"]') : null;
  }
  function setRadio(el, val, ccBug) {
    var g = groupOf(el, ccBug);
    if (!g) { el.classList.add('visited'); return; }
    Array.prototype.forEach.call(g, function (r) { if (val !== null && r.value === val) r.checked = true; mark(r); });
  }
  // A2Perf's visitGroup(id, value) (ActionKind::Visit in dom.rs) on element n, the owner of the
  // acted element's id (Website::id_owner).
  function visit(n, val, ccBug) {
    var el = nodes[n];
    if (!el || !el.id || !visible(el)) return;
    el.classList.add('visited');
    var t = el.tagName, ty = el.type;
    if (t === 'SELECT' || (t === 'INPUT' && (ty === 'text' || ty === 'number' || ty === 'password' || ty === 'email'))) {
      el.value = val === null ? '' : val;
    } else if (t === 'INPUT' && ty === 'radio') setRadio(el, val, ccBug);
    else if (val === 'true' || val === '1' || !(t === 'INPUT' && ty === 'checkbox')) el.click();
  }
  // kind 0 = click, 1 = type val, 2 = A2Perf's visit with val (or null).
  a2p.step = function (kind, n, val, ccBug) {
    var el = nodes[n];
    if (kind === 2) visit(n, val, ccBug);
    else if (el && visible(el)) {
      var ctl = el.tagName === 'INPUT' || el.tagName === 'SELECT';
      var radio = el.tagName === 'INPUT' && el.type === 'radio';
      if (kind === 0) {
        if (ctl) el.focus({ preventScroll: true });
        if (!radio || groupOf(el, ccBug)) el.click();
        mark(el);
      } else if (ctl) {
        if (el.type === 'checkbox') el.checked = (val === 'true');
        else if (radio) setRadio(el, val, ccBug);
        else el.value = val;
        el.focus({ preventScroll: true });
        mark(el);
      }
    }
    return a2p.state();
  };
  window.a2p = a2p;
  }
  // Replaces the website without a navigation (the Chromium backend's reset).
  window.a2pLoad = function (html, profile) {
    var ae = document.activeElement;
    if (ae && ae !== document.body && ae.blur) ae.blur();
    document.getElementById('query').textContent = profile;
    document.getElementById('a2p-root').innerHTML = html;
    init();
    return window.a2p.state();
  };
  init();
})();
"#;
