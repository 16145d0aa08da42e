//! A parser for the subset of RON that experiment files use, keeping the location of every key and
//! value so that errors can point at them.
//!
//! Supported: `//` and nested `/* */` comments; `true`/`false`; `None` and `Some(v)`; integers
//! (with `_` separators); floats (`3.0`, `1e-4`, `inf`, `-inf`, `NaN`); strings with escapes and raw
//! strings `r"…"`/`r#"…"#`; lists `[a, b]`; structs `(key: value)`; maps `{"key": value}`; trailing
//! commas. Not supported (a syntax error says so): tuples, named structs and enum variants, chars,
//! hex/octal/binary integers.

use std::path::Path;
use std::sync::Arc;

use super::error::{ConfigError, Location};
use crate::value::Value;

/// A value with the place it was written.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// The value.
    pub value: NodeValue,
    /// Where it was written.
    pub location: Location,
}

/// A configuration value whose children keep their locations.
#[derive(Clone, Debug, PartialEq)]
pub enum NodeValue {
    /// `None`.
    Null,
    /// `true` / `false`.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A float.
    Float(f64),
    /// A string.
    Str(String),
    /// A list.
    List(Vec<Node>),
    /// A struct `(k: v)` or map `{"k": v}`, in written order, keys unique.
    Struct(Vec<Field>),
}

/// One `key: value` entry of a struct or map.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// The key.
    pub key: String,
    /// Where the key was written.
    pub key_location: Location,
    /// The value.
    pub value: Node,
}

impl Node {
    /// A node at `location`.
    pub fn new(value: NodeValue, location: Location) -> Self {
        Self { value, location }
    }

    /// The field `key` of a struct node.
    pub fn field(&self, key: &str) -> Option<&Field> {
        match &self.value {
            NodeValue::Struct(fields) => fields.iter().find(|f| f.key == key),
            _ => None,
        }
    }

    /// The type's name as used in error messages.
    pub fn type_name(&self) -> &'static str {
        match &self.value {
            NodeValue::Null => "none",
            NodeValue::Bool(_) => "bool",
            NodeValue::Int(_) => "integer",
            NodeValue::Float(_) => "float",
            NodeValue::Str(_) => "string",
            NodeValue::List(_) => "list",
            NodeValue::Struct(_) => "struct",
        }
    }

    /// The plain value, locations dropped (structs and maps become [`Value::Map`]).
    pub fn to_value(&self) -> Value {
        match &self.value {
            NodeValue::Null => Value::Null,
            NodeValue::Bool(b) => Value::Bool(*b),
            NodeValue::Int(i) => Value::Int(*i),
            NodeValue::Float(x) => Value::Float(*x),
            NodeValue::Str(s) => Value::Str(s.clone()),
            NodeValue::List(items) => Value::List(items.iter().map(Node::to_value).collect()),
            NodeValue::Struct(fields) => Value::Map(
                fields
                    .iter()
                    .map(|f| (f.key.clone(), f.value.to_value()))
                    .collect(),
            ),
        }
    }
}

/// Parses one RON value (the whole text; comments and whitespace around it are allowed).
///
/// `path` names the text in locations (`path:line:column`, counted from 1; columns count
/// characters). A leading byte-order mark is ignored.
///
/// ```
/// use a2perf_core::config::{parse_str, NodeValue};
/// let node = parse_str("(lr: 1e-4, layers: [64, 64],)", std::path::Path::new("x.ron")).unwrap();
/// assert_eq!(node.field("lr").unwrap().value.value, NodeValue::Float(1e-4));
/// assert_eq!(node.field("layers").unwrap().value.location.to_string(), "x.ron:1:20");
/// ```
pub fn parse_str(text: &str, path: &Path) -> Result<Node, ConfigError> {
    let path: Arc<Path> = Arc::from(path);
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    Parser::new(text, Origin::File(path)).parse_document()
}

/// Parses an override value: every node gets `Location::Override(text)`.
pub(crate) fn parse_override_value(value: &str, whole: &Arc<str>) -> Result<Node, ConfigError> {
    Parser::new(value, Origin::Override(Arc::clone(whole))).parse_document()
}

#[derive(Clone)]
enum Origin {
    File(Arc<Path>),
    Override(Arc<str>),
}

/// Guards against stack overflow on adversarial input; real configs nest 3–4 deep.
const MAX_DEPTH: usize = 64;

struct Parser {
    chars: Vec<char>,
    pos: usize,
    line: u32,
    column: u32,
    origin: Origin,
}

impl Parser {
    fn new(text: &str, origin: Origin) -> Self {
        Self {
            chars: text.chars().collect(),
            pos: 0,
            line: 1,
            column: 1,
            origin,
        }
    }

    fn here(&self) -> Location {
        match &self.origin {
            Origin::File(path) => Location::file(path, self.line, self.column),
            Origin::Override(text) => Location::Override(Arc::clone(text)),
        }
    }

    fn error_at(&self, location: Location, message: impl Into<String>) -> ConfigError {
        ConfigError::Syntax {
            location,
            message: message.into(),
        }
    }

    fn error(&self, message: impl Into<String>) -> ConfigError {
        self.error_at(self.here(), message)
    }

    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }

    fn peek_at(&self, offset: usize) -> Option<char> {
        self.chars.get(self.pos + offset).copied()
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.peek()?;
        self.pos += 1;
        if c == '\n' {
            self.line += 1;
            self.column = 1;
        } else {
            self.column += 1;
        }
        Some(c)
    }

    fn skip_trivia(&mut self) -> Result<(), ConfigError> {
        loop {
            match (self.peek(), self.peek_at(1)) {
                (Some(c), _) if c.is_whitespace() => {
                    self.bump();
                }
                (Some('/'), Some('/')) => {
                    while self.peek().is_some_and(|c| c != '\n') {
                        self.bump();
                    }
                }
                (Some('/'), Some('*')) => {
                    let start = self.here();
                    self.bump();
                    self.bump();
                    let mut depth = 1usize;
                    while depth > 0 {
                        match (self.peek(), self.peek_at(1)) {
                            (None, _) => {
                                return Err(self.error_at(start, "unterminated `/*` comment"));
                            }
                            (Some('*'), Some('/')) => {
                                self.bump();
                                self.bump();
                                depth -= 1;
                            }
                            (Some('/'), Some('*')) => {
                                self.bump();
                                self.bump();
                                depth += 1;
                            }
                            _ => {
                                self.bump();
                            }
                        }
                    }
                }
                _ => return Ok(()),
            }
        }
    }

    fn parse_document(mut self) -> Result<Node, ConfigError> {
        self.skip_trivia()?;
        if self.peek().is_none() {
            return Err(self.error("expected a value, found end of input"));
        }
        let node = self.parse_value(0)?;
        self.skip_trivia()?;
        if let Some(c) = self.peek() {
            return Err(self.error(format!("unexpected `{c}` after the value")));
        }
        Ok(node)
    }

    fn expect(&mut self, want: char) -> Result<(), ConfigError> {
        self.skip_trivia()?;
        match self.peek() {
            Some(c) if c == want => {
                self.bump();
                Ok(())
            }
            Some(c) => Err(self.error(format!("expected `{want}`, found `{c}`"))),
            None => Err(self.error(format!("expected `{want}`, found end of input"))),
        }
    }

    fn parse_value(&mut self, depth: usize) -> Result<Node, ConfigError> {
        self.skip_trivia()?;
        if depth > MAX_DEPTH {
            return Err(self.error(format!("values nested more than {MAX_DEPTH} deep")));
        }
        let location = self.here();
        let value = match self.peek() {
            None => return Err(self.error("expected a value, found end of input")),
            Some('(') => self.parse_struct(depth)?,
            Some('{') => self.parse_map(depth)?,
            Some('[') => self.parse_list(depth)?,
            Some('"') => NodeValue::Str(self.parse_string()?),
            Some('r') if matches!(self.peek_at(1), Some('"' | '#')) => {
                NodeValue::Str(self.parse_raw_string()?)
            }
            Some(c) if c.is_ascii_digit() || c == '-' || c == '+' || c == '.' => {
                self.parse_number()?
            }
            Some(c) if c.is_alphabetic() || c == '_' => {
                let ident = self.parse_ident();
                match ident.as_str() {
                    "true" => NodeValue::Bool(true),
                    "false" => NodeValue::Bool(false),
                    "None" => NodeValue::Null,
                    "inf" => NodeValue::Float(f64::INFINITY),
                    "NaN" => NodeValue::Float(f64::NAN),
                    "Some" => {
                        self.expect('(')?;
                        let inner = self.parse_value(depth + 1)?;
                        self.skip_trivia()?;
                        if self.peek() == Some(',') {
                            self.bump();
                        }
                        self.expect(')')?;
                        return Ok(Node::new(inner.value, location));
                    }
                    _ => {
                        return Err(self.error_at(
                            location,
                            format!(
                                "unexpected identifier `{ident}` (strings need double quotes: \"{ident}\")"
                            ),
                        ));
                    }
                }
            }
            Some(c) => return Err(self.error(format!("expected a value, found `{c}`"))),
        };
        Ok(Node::new(value, location))
    }

    fn parse_ident(&mut self) -> String {
        let mut s = String::new();
        while let Some(c) = self.peek() {
            if c.is_alphanumeric() || c == '_' {
                s.push(c);
                self.bump();
            } else {
                break;
            }
        }
        s
    }

    fn parse_number(&mut self) -> Result<NodeValue, ConfigError> {
        let start = self.here();
        let mut text = String::new();
        if let Some(sign @ ('-' | '+')) = self.peek() {
            self.bump();
            if sign == '-' {
                text.push('-');
            }
            if self.peek().is_some_and(char::is_alphabetic) {
                let ident = self.parse_ident();
                return if ident == "inf" {
                    Ok(NodeValue::Float(if sign == '-' {
                        f64::NEG_INFINITY
                    } else {
                        f64::INFINITY
                    }))
                } else {
                    Err(self.error_at(start, format!("expected a number after `{sign}`")))
                };
            }
        }
        let mut is_float = false;
        while let Some(c) = self.peek() {
            match c {
                '0'..='9' => text.push(c),
                '_' => {}
                '.' => {
                    is_float = true;
                    text.push(c);
                }
                'e' | 'E' => {
                    is_float = true;
                    text.push(c);
                    if let Some(s @ ('-' | '+')) = self.peek_at(1) {
                        self.bump();
                        text.push(s);
                    }
                }
                _ => break,
            }
            self.bump();
        }
        if let Some(c) = self.peek().filter(|c| c.is_alphanumeric()) {
            return Err(self.error(format!("unexpected `{c}` in number `{text}`")));
        }
        if is_float {
            text.parse::<f64>()
                .map(NodeValue::Float)
                .map_err(|_| self.error_at(start, format!("invalid number `{text}`")))
        } else {
            text.parse::<i64>().map(NodeValue::Int).map_err(|e| {
                let why = if text.chars().any(|c| c.is_ascii_digit()) {
                    format!("integer `{text}` out of range ({e})")
                } else {
                    format!("invalid number `{text}`")
                };
                self.error_at(start, why)
            })
        }
    }

    fn parse_string(&mut self) -> Result<String, ConfigError> {
        let start = self.here();
        self.bump(); // opening quote
        let mut s = String::new();
        loop {
            let at = self.here();
            match self.bump() {
                None => return Err(self.error_at(start, "unterminated string")),
                Some('"') => return Ok(s),
                Some('\\') => match self.bump() {
                    Some('n') => s.push('\n'),
                    Some('t') => s.push('\t'),
                    Some('r') => s.push('\r'),
                    Some('0') => s.push('\0'),
                    Some('\\') => s.push('\\'),
                    Some('"') => s.push('"'),
                    Some('\'') => s.push('\''),
                    Some('u') => s.push(self.parse_unicode_escape(at)?),
                    Some(c) => {
                        return Err(self.error_at(at, format!("unknown escape `\\{c}`")));
                    }
                    None => return Err(self.error_at(start, "unterminated string")),
                },
                Some(c) => s.push(c),
            }
        }
    }

    fn parse_unicode_escape(&mut self, at: Location) -> Result<char, ConfigError> {
        let bad = |p: &Self| p.error_at(at.clone(), "invalid unicode escape (use `\\u{1F600}`)");
        if self.bump() != Some('{') {
            return Err(bad(self));
        }
        let mut hex = String::new();
        loop {
            match self.bump() {
                Some('}') => break,
                Some(c) if c.is_ascii_hexdigit() && hex.len() < 6 => hex.push(c),
                _ => return Err(bad(self)),
            }
        }
        u32::from_str_radix(&hex, 16)
            .ok()
            .and_then(char::from_u32)
            .ok_or_else(|| bad(self))
    }

    fn parse_raw_string(&mut self) -> Result<String, ConfigError> {
        let start = self.here();
        self.bump(); // r
        let mut hashes = 0;
        while self.peek() == Some('#') {
            self.bump();
            hashes += 1;
        }
        if self.bump() != Some('"') {
            return Err(self.error_at(start, "expected `\"` to open the raw string"));
        }
        let mut s = String::new();
        loop {
            match self.bump() {
                None => return Err(self.error_at(start, "unterminated raw string")),
                Some('"') if (0..hashes).all(|i| self.peek_at(i) == Some('#')) => {
                    for _ in 0..hashes {
                        self.bump();
                    }
                    return Ok(s);
                }
                Some(c) => s.push(c),
            }
        }
    }

    fn parse_list(&mut self, depth: usize) -> Result<NodeValue, ConfigError> {
        self.bump(); // [
        let mut items = Vec::new();
        loop {
            self.skip_trivia()?;
            if self.peek() == Some(']') {
                self.bump();
                return Ok(NodeValue::List(items));
            }
            items.push(self.parse_value(depth + 1)?);
            self.skip_trivia()?;
            match self.peek() {
                Some(',') => {
                    self.bump();
                }
                Some(']') => {}
                Some(c) => return Err(self.error(format!("expected `,` or `]`, found `{c}`"))),
                None => return Err(self.error("unterminated list: expected `]`")),
            }
        }
    }

    fn parse_struct(&mut self, depth: usize) -> Result<NodeValue, ConfigError> {
        self.bump(); // (
        let mut fields: Vec<Field> = Vec::new();
        loop {
            self.skip_trivia()?;
            let key_location = self.here();
            let key = match self.peek() {
                Some(')') => {
                    self.bump();
                    return Ok(NodeValue::Struct(fields));
                }
                Some(c) if c.is_alphabetic() || c == '_' => self.parse_ident(),
                Some('"') => {
                    return Err(self.error(
                        "struct keys are bare identifiers (`key: value`); quoted keys belong in maps `{\"key\": value}`",
                    ));
                }
                Some(c) => {
                    return Err(self.error(format!(
                        "expected a key (`key: value`) or `)`, found `{c}` (tuples are not supported)"
                    )));
                }
                None => return Err(self.error("unterminated struct: expected `)`")),
            };
            self.field_rest(&mut fields, key, key_location, ')', depth)?;
        }
    }

    fn parse_map(&mut self, depth: usize) -> Result<NodeValue, ConfigError> {
        self.bump(); // {
        let mut fields: Vec<Field> = Vec::new();
        loop {
            self.skip_trivia()?;
            let key_location = self.here();
            let key = match self.peek() {
                Some('}') => {
                    self.bump();
                    return Ok(NodeValue::Struct(fields));
                }
                Some('"') => self.parse_string()?,
                Some(c) => {
                    return Err(self.error(format!(
                        "expected a string key (`\"key\": value`) or `}}`, found `{c}`"
                    )));
                }
                None => return Err(self.error("unterminated map: expected `}`")),
            };
            self.field_rest(&mut fields, key, key_location, '}', depth)?;
        }
    }

    /// Parses `: value` and the separator after a key, rejecting duplicates.
    fn field_rest(
        &mut self,
        fields: &mut Vec<Field>,
        key: String,
        key_location: Location,
        close: char,
        depth: usize,
    ) -> Result<(), ConfigError> {
        self.expect(':')?;
        let value = self.parse_value(depth + 1)?;
        if let Some(first) = fields.iter().find(|f| f.key == key) {
            return Err(ConfigError::DuplicateKey {
                location: key_location,
                key,
                first: first.key_location.clone(),
            });
        }
        fields.push(Field {
            key,
            key_location,
            value,
        });
        self.skip_trivia()?;
        match self.peek() {
            Some(',') => {
                self.bump();
                Ok(())
            }
            Some(c) if c == close => Ok(()),
            Some(c) => Err(self.error(format!("expected `,` or `{close}`, found `{c}`"))),
            None => Err(self.error(format!("expected `{close}`, found end of input"))),
        }
    }
}
