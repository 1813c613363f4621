//! The one CSV codec of the harness: every CSV file it writes or reads goes through
//! here, as a table of serde records (one struct per file, its fields the columns in
//! order).
//!
//! - Writing quotes as RFC 4180 says (through the `csv` crate, so that names with
//!   commas or quotes survive) and replaces the file atomically
//!   ([`crate::report::write_atomically`]).
//! - Numbers are written as each record's fields say ([`display`], [`fixed`],
//!   [`scientific`]): the `csv` crate's own float format is not Rust's `{}`, and the
//!   files keep the formats they have always had, so that two runs compare as text.
//! - Reading checks the header against the record's fields, parses every field with
//!   its type's [`std::str::FromStr`] (as `"1"`, `"1.0"`, `"1e0"` and `"inf"` all read
//!   as an `f64`), and names the file, line, column and text of any field it refuses.

use std::fmt::Display;
use std::path::Path;
use std::str::FromStr;

use anyhow::{Context, bail};
use serde::de::{self, DeserializeOwned, IntoDeserializer, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Write `records` to `path` as CSV, atomically: a header line of the record's field
/// names (written even when there is no record), then a line per record. The file
/// reads back with [`read_records`].
pub fn write_records<T: Serialize + DeserializeOwned>(
    path: &Path,
    records: &[T],
) -> anyhow::Result<()> {
    write(path, Some(header::<T>()), records)
}

/// Write `rows` to `path` as CSV, atomically, for a table nothing reads back (its rows
/// need not deserialise): the header is the first row's field names, and a table of no
/// row is an empty file.
pub fn write_table<T: Serialize>(path: &Path, rows: &[T]) -> anyhow::Result<()> {
    write(path, None, rows)
}

fn write<T: Serialize>(path: &Path, header: Option<&[&str]>, rows: &[T]) -> anyhow::Result<()> {
    let mut writer = csv::WriterBuilder::new()
        .has_headers(header.is_none())
        .from_writer(Vec::new());
    if let Some(header) = header {
        writer
            .write_record(header)
            .with_context(|| format!("encoding the header of {}", path.display()))?;
    }
    for (i, row) in rows.iter().enumerate() {
        writer
            .serialize(row)
            .with_context(|| format!("encoding row {} of {}", i + 1, path.display()))?;
    }
    let bytes = writer
        .into_inner()
        .with_context(|| format!("encoding {}", path.display()))?;
    crate::report::write_atomically(path, &bytes)
}

/// The records of the CSV file `path`, whose header must be exactly the field names of
/// `T` ([`header`]); `what` names the kind of file in errors (`runs CSV`). An error
/// names the file and the line (as the `csv` crate counts them: quoted line breaks
/// and blank lines included), and for a field it refuses, the column and its text.
pub fn read_records<T: DeserializeOwned>(path: &Path, what: &str) -> anyhow::Result<Vec<T>> {
    let header = header::<T>();
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_path(path)
        .with_context(|| format!("reading {}", path.display()))?;
    let found = reader
        .headers()
        .with_context(|| format!("reading {}", path.display()))?
        .clone();
    if found.iter().ne(header.iter().copied()) {
        bail!("{}: not a {what} (unexpected header)", path.display());
    }
    let mut records = Vec::new();
    for row in reader.records() {
        let row = row.with_context(|| format!("reading {}", path.display()))?;
        let line = row.position().map_or(0, |p| p.line());
        if row.len() != header.len() {
            bail!(
                "{}:{line}: {} fields, expected {}",
                path.display(),
                row.len(),
                header.len()
            );
        }
        let fields = header.iter().copied().zip(row.iter());
        let record = T::deserialize(Row {
            fields,
            current: ("", ""),
        })
        .map_err(|e| anyhow::anyhow!("{}:{line}: {e}", path.display()))?;
        records.push(record);
    }
    Ok(records)
}

/// The field names of the struct `T`, in order: the header of its CSV files.
///
/// Read from `T`'s `Deserialize` (which names every field it expects), so that the
/// header is written once, by the struct.
///
/// # Panics
///
/// If `T` does not deserialise from a struct: a programming error, not a file's.
pub fn header<T: DeserializeOwned>() -> &'static [&'static str] {
    let mut names = None;
    let _ = T::deserialize(FieldNames(&mut names));
    names.expect("a CSV record is a struct with named fields")
}

/// `serialize_with`: a value as its `Display` (`{}`: `0.5`, `1`, `rule2`).
pub fn display<T: Display, S: Serializer>(value: &T, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_str(value)
}

/// `serialize_with`: a number with `DIGITS` digits after the point (`{:.DIGITS}`).
pub fn fixed<const DIGITS: usize, S: Serializer>(
    value: &f64,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    serializer.collect_str(&format_args!("{:.*}", DIGITS, value))
}

/// `serialize_with`: a number in scientific notation with `DIGITS` digits after the
/// point (`{:.DIGITS e}`: `1.000000e-3`).
pub fn scientific<const DIGITS: usize, S: Serializer>(
    value: &f64,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    serializer.collect_str(&format_args!("{:.*e}", DIGITS, value))
}

/// `deserialize_with`: a value by its `FromStr` (the names of [`vvs::Method`] and
/// [`vvs::StopReason`], which their `Display` writes).
pub fn from_str<'de, T, D>(deserializer: D) -> Result<T, D::Error>
where
    T: FromStr,
    T::Err: Display,
    D: Deserializer<'de>,
{
    let text = String::deserialize(deserializer)?;
    text.parse().map_err(de::Error::custom)
}

/// One row as the struct a record deserialises from: a map from the header's names to
/// the row's fields.
struct Row<'a, I> {
    fields: I,
    /// The name and text of the field whose name was given last.
    current: (&'static str, &'a str),
}

impl<'de, 'a, I: Iterator<Item = (&'static str, &'a str)>> Deserializer<'de> for Row<'a, I> {
    type Error = de::value::Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        visitor.visit_map(self)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes
        byte_buf option unit unit_struct newtype_struct seq tuple tuple_struct map struct
        enum identifier ignored_any
    }
}

impl<'de, 'a, I: Iterator<Item = (&'static str, &'a str)>> de::MapAccess<'de> for Row<'a, I> {
    type Error = de::value::Error;

    fn next_key_seed<K: de::DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, Self::Error> {
        let Some((name, value)) = self.fields.next() else {
            return Ok(None);
        };
        self.current = (name, value);
        seed.deserialize(name.into_deserializer()).map(Some)
    }

    fn next_value_seed<V: de::DeserializeSeed<'de>>(
        &mut self,
        seed: V,
    ) -> Result<V::Value, Self::Error> {
        let (name, value) = self.current;
        seed.deserialize(Field(value))
            .map_err(|e| de::Error::custom(format_args!("field {name}: `{value}`: {e}")))
    }
}

/// One field of a row: a value parsed from its text by its type's `FromStr`; an empty
/// field is `None` for an `Option`.
struct Field<'a>(&'a str);

macro_rules! parse_field {
    ($($method:ident => $visit:ident,)*) => {
        $(
            fn $method<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
                visitor.$visit(self.0.parse().map_err(de::Error::custom)?)
            }
        )*
    };
}

impl<'de> Deserializer<'de> for Field<'_> {
    type Error = de::value::Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        visitor.visit_str(self.0)
    }

    parse_field! {
        deserialize_bool => visit_bool,
        deserialize_i8 => visit_i8,
        deserialize_i16 => visit_i16,
        deserialize_i32 => visit_i32,
        deserialize_i64 => visit_i64,
        deserialize_i128 => visit_i128,
        deserialize_u8 => visit_u8,
        deserialize_u16 => visit_u16,
        deserialize_u32 => visit_u32,
        deserialize_u64 => visit_u64,
        deserialize_u128 => visit_u128,
        deserialize_f32 => visit_f32,
        deserialize_f64 => visit_f64,
        deserialize_char => visit_char,
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        if self.0.is_empty() {
            visitor.visit_none()
        } else {
            visitor.visit_some(self)
        }
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        name: &'static str,
        variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        // A unit variant by its name.
        de::value::StrDeserializer::<Self::Error>::new(self.0)
            .deserialize_enum(name, variants, visitor)
    }

    serde::forward_to_deserialize_any! {
        str string bytes byte_buf unit unit_struct seq tuple tuple_struct map struct
        identifier ignored_any
    }
}

/// A deserialiser that only asks the struct it is given for its field names.
struct FieldNames<'a>(&'a mut Option<&'static [&'static str]>);

impl<'de> Deserializer<'de> for FieldNames<'_> {
    type Error = de::value::Error;

    fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, Self::Error> {
        Err(de::Error::custom("not a struct"))
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        _visitor: V,
    ) -> Result<V::Value, Self::Error> {
        *self.0 = Some(fields);
        Err(de::Error::custom("the field names only"))
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes
        byte_buf option unit unit_struct newtype_struct seq tuple tuple_struct map
        enum identifier ignored_any
    }
}
