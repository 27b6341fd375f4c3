//! A thin checked view over a parsed TOML document that keeps every value's line, so that
//! each complaint about a scene names the file, the key path and the line.

use std::path::Path;

use toml::de::{DeTable, DeValue};
use toml::Spanned;

use crate::error::InputError;

/// The source text of one file, for turning byte offsets into line numbers.
pub struct Source<'a> {
    pub file: &'a Path,
    line_starts: Vec<usize>,
}

impl<'a> Source<'a> {
    pub fn new(file: &'a Path, text: &str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Source { file, line_starts }
    }

    pub fn line_of(&self, byte: usize) -> usize {
        self.line_starts.partition_point(|&s| s <= byte)
    }

    pub fn error(&self, key: &str, byte: Option<usize>, message: impl Into<String>) -> InputError {
        InputError::new(self.file, key, byte.map(|b| self.line_of(b)), message)
    }
}

/// A value of the document with its dotted key path.
#[derive(Clone, Copy)]
pub struct Node<'s, 'v> {
    pub src: &'s Source<'s>,
    pub path: &'v str,
    pub value: &'v Spanned<DeValue<'v>>,
}

/// Owned key path, so that children can borrow it.
pub fn child_path(parent: &str, key: &str) -> String {
    if parent.is_empty() {
        key.to_string()
    } else {
        format!("{parent}.{key}")
    }
}

pub fn index_path(parent: &str, i: usize) -> String {
    format!("{parent}[{i}]")
}

fn type_name(v: &DeValue) -> &'static str {
    match v {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a number",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a date",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

pub type R<T> = Result<T, InputError>;

impl<'s, 'v> Node<'s, 'v> {
    pub fn err(&self, message: impl Into<String>) -> InputError {
        self.src.error(self.path, Some(self.value.span().start), message)
    }

    fn wrong_type(&self, expected: &str) -> InputError {
        self.err(format!("expected {expected}, found {}", type_name(self.value.get_ref())))
    }

    /// Any finite number (integers are accepted where numbers are).
    pub fn f64(&self) -> R<f64> {
        let x = match self.value.get_ref() {
            DeValue::Float(f) => f.as_str().replace('_', "").parse::<f64>().map_err(|_| self.err("not a number"))?,
            DeValue::Integer(i) => i64::from_str_radix(&i.as_str().replace('_', ""), i.radix())
                .map_err(|_| self.err("integer out of range"))? as f64,
            _ => return Err(self.wrong_type("a number")),
        };
        if !x.is_finite() {
            return Err(self.err(format!("{x} is not a finite number")));
        }
        Ok(x)
    }

    pub fn u64(&self) -> R<u64> {
        let x = self.f64()?;
        if x < 0.0 || x.fract() != 0.0 || x > 9.0e18 {
            return Err(self.err(format!("expected a non-negative whole number, found {x}")));
        }
        Ok(x as u64)
    }

    pub fn str(&self) -> R<&'v str> {
        match self.value.get_ref() {
            DeValue::String(s) => Ok(s.as_ref()),
            _ => Err(self.wrong_type("a string")),
        }
    }

    pub fn array(&self) -> R<&'v [Spanned<DeValue<'v>>]> {
        match self.value.get_ref() {
            DeValue::Array(a) => Ok(a.as_ref()),
            _ => Err(self.wrong_type("an array")),
        }
    }

    pub fn is_table(&self) -> bool {
        matches!(self.value.get_ref(), DeValue::Table(_))
    }

    pub fn is_number(&self) -> bool {
        matches!(self.value.get_ref(), DeValue::Float(_) | DeValue::Integer(_))
    }

    pub fn table(&self) -> R<Table<'s, 'v>> {
        match self.value.get_ref() {
            DeValue::Table(t) => Ok(Table { src: self.src, path: self.path, table: t, start: self.value.span().start }),
            _ => Err(self.wrong_type("a table")),
        }
    }

    /// `[x, y, z]`, finite.
    pub fn vec3(&self) -> R<[f64; 3]> {
        let items = self.array()?;
        if items.len() != 3 {
            return Err(self.err(format!("expected a point [x, y, z], found {} numbers", items.len())));
        }
        let mut out = [0.0; 3];
        for (i, item) in items.iter().enumerate() {
            let p = index_path(self.path, i);
            out[i] = Node { src: self.src, path: &p, value: item }.f64()?;
        }
        Ok(out)
    }

    /// Calls `f` on each element with its own path.
    pub fn each<T>(&self, mut f: impl FnMut(Node<'s, '_>) -> R<T>) -> R<Vec<T>> {
        let items = self.array()?;
        let mut out = Vec::with_capacity(items.len());
        for (i, item) in items.iter().enumerate() {
            let p = index_path(self.path, i);
            out.push(f(Node { src: self.src, path: &p, value: item })?);
        }
        Ok(out)
    }
}

/// A table of the document. Every table is checked against its list of allowed keys.
#[derive(Clone, Copy)]
pub struct Table<'s, 'v> {
    pub src: &'s Source<'s>,
    pub path: &'v str,
    pub table: &'v DeTable<'v>,
    pub start: usize,
}

impl<'s, 'v> Table<'s, 'v> {
    pub fn err(&self, message: impl Into<String>) -> InputError {
        self.src.error(self.path, Some(self.start), message)
    }

    /// An error at `key`'s value (or at the table when the key is absent).
    pub fn err_at(&self, key: &str, message: impl Into<String>) -> InputError {
        let byte = self.table.get(key).map_or(self.start, |v| v.span().start);
        self.src.error(&child_path(self.path, key), Some(byte), message)
    }

    /// Rejects any key not in `allowed`, naming the allowed ones.
    pub fn allow(&self, allowed: &[&str]) -> R<()> {
        for (key, value) in self.table.iter() {
            if !allowed.contains(&key.get_ref().as_ref()) {
                return Err(self.src.error(
                    &child_path(self.path, key.get_ref()),
                    Some(key.span().start.min(value.span().start)),
                    format!("unknown key `{}`; allowed keys here: {}", key.get_ref(), allowed.join(", ")),
                ));
            }
        }
        Ok(())
    }

    pub fn keys(&self) -> impl Iterator<Item = &'v str> {
        self.table.keys().map(|k| k.get_ref().as_ref())
    }

    pub fn has(&self, key: &str) -> bool {
        self.table.get(key).is_some()
    }

    /// Looks up `key`; the closure receives the child node with its full path.
    pub fn with<T>(&self, key: &str, f: impl FnOnce(Node<'s, '_>) -> R<T>) -> R<Option<T>> {
        match self.table.get(key) {
            None => Ok(None),
            Some(v) => {
                let p = child_path(self.path, key);
                f(Node { src: self.src, path: &p, value: v }).map(Some)
            }
        }
    }

    pub fn require<T>(&self, key: &str, f: impl FnOnce(Node<'s, '_>) -> R<T>) -> R<T> {
        match self.with(key, f)? {
            Some(v) => Ok(v),
            None => Err(self.src.error(
                &child_path(self.path, key),
                Some(self.start),
                format!("missing required key `{key}`"),
            )),
        }
    }

    pub fn str(&self, key: &str) -> R<Option<String>> {
        self.with(key, |n| n.str().map(str::to_string))
    }

    pub fn vec3(&self, key: &str) -> R<Option<[f64; 3]>> {
        self.with(key, |n| n.vec3())
    }

    pub fn req_vec3(&self, key: &str) -> R<[f64; 3]> {
        self.require(key, |n| n.vec3())
    }

    pub fn req_f64(&self, key: &str) -> R<f64> {
        self.require(key, |n| n.f64())
    }

    pub fn req_str(&self, key: &str) -> R<String> {
        self.require(key, |n| n.str().map(str::to_string))
    }

    /// The line of `key`'s value, or of the table when the key is absent.
    pub fn line_of_key(&self, key: &str) -> usize {
        let byte = self.table.get(key).map(|v| v.span().start).unwrap_or(self.start);
        self.src.line_of(byte)
    }
}
