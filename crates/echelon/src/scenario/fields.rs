//! The names of the fields a value serialises, as serde's derive writes them:
//! how the builder asks which fields a type has, or which of a section's
//! optional fields are given, without listing the names again.

use std::fmt;

use serde::Serialize;
use serde::ser::{self, Impossible, SerializeStruct};

/// The names of the fields `value` writes, in declaration order: a field
/// holding a struct gives that struct's fields in its place, and an optional
/// field left out (`skip_serializing_if`) gives nothing. `None` unless
/// `value` is a struct whose fields are structs or plain values (numbers,
/// strings, options, unit enum variants); sequences and maps are not read.
pub(super) fn field_names<T: Serialize + ?Sized>(value: &T) -> Option<Vec<&'static str>> {
    value.serialize(Names).ok().flatten()
}

/// What [`Names`] does not read: a sequence, a map, a tuple, a variant with
/// data.
#[derive(Debug)]
struct Unread;

impl fmt::Display for Unread {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("only structs and plain values are read")
    }
}

impl std::error::Error for Unread {}

impl ser::Error for Unread {
    fn custom<T: fmt::Display>(_: T) -> Self {
        Unread
    }
}

/// Serialises a struct into its fields' names (`Some`), a plain value into
/// `None`.
struct Names;

/// A struct's field names so far.
struct Fields(Vec<&'static str>);

type Out = Option<Vec<&'static str>>;

impl SerializeStruct for Fields {
    type Ok = Out;
    type Error = Unread;

    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), Unread> {
        match value.serialize(Names)? {
            Some(inner) => self.0.extend(inner),
            None => self.0.push(key),
        }
        Ok(())
    }

    fn end(self) -> Result<Out, Unread> {
        Ok(Some(self.0))
    }
}

/// Serialiser methods for plain values: no fields of their own.
macro_rules! plain_values {
    ($($method:ident($t:ty)),* $(,)?) => {
        $(fn $method(self, _: $t) -> Result<Out, Unread> {
            Ok(None)
        })*
    };
}

impl ser::Serializer for Names {
    type Ok = Out;
    type Error = Unread;
    type SerializeSeq = Impossible<Out, Unread>;
    type SerializeTuple = Impossible<Out, Unread>;
    type SerializeTupleStruct = Impossible<Out, Unread>;
    type SerializeTupleVariant = Impossible<Out, Unread>;
    type SerializeMap = Impossible<Out, Unread>;
    type SerializeStruct = Fields;
    type SerializeStructVariant = Impossible<Out, Unread>;

    fn serialize_struct(self, _: &'static str, len: usize) -> Result<Fields, Unread> {
        Ok(Fields(Vec::with_capacity(len)))
    }

    plain_values! {
        serialize_bool(bool),
        serialize_i8(i8),
        serialize_i16(i16),
        serialize_i32(i32),
        serialize_i64(i64),
        serialize_u8(u8),
        serialize_u16(u16),
        serialize_u32(u32),
        serialize_u64(u64),
        serialize_f32(f32),
        serialize_f64(f64),
        serialize_char(char),
        serialize_str(&str),
        serialize_bytes(&[u8]),
        serialize_unit_struct(&'static str),
    }
    fn serialize_none(self) -> Result<Out, Unread> {
        Ok(None)
    }
    fn serialize_unit(self) -> Result<Out, Unread> {
        Ok(None)
    }
    fn serialize_some<T: Serialize + ?Sized>(self, _: &T) -> Result<Out, Unread> {
        Ok(None)
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
    ) -> Result<Out, Unread> {
        Ok(None)
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        value: &T,
    ) -> Result<Out, Unread> {
        value.serialize(self)
    }

    // Not read.
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: &T,
    ) -> Result<Out, Unread> {
        Err(Unread)
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Self::SerializeSeq, Unread> {
        Err(Unread)
    }
    fn serialize_tuple(self, _: usize) -> Result<Self::SerializeTuple, Unread> {
        Err(Unread)
    }
    fn serialize_tuple_struct(
        self,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeTupleStruct, Unread> {
        Err(Unread)
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeTupleVariant, Unread> {
        Err(Unread)
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self::SerializeMap, Unread> {
        Err(Unread)
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeStructVariant, Unread> {
        Err(Unread)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct Inner {
        a: f64,
        b: Option<String>,
    }

    #[derive(Serialize)]
    struct Outer {
        first: u8,
        inner: Inner,
        #[serde(skip_serializing_if = "Option::is_none")]
        left_out: Option<f64>,
        #[serde(skip_serializing_if = "Option::is_none")]
        given: Option<f64>,
        last: bool,
    }

    #[test]
    fn names_in_order_nested_in_place_skipped_left_out() {
        let v = Outer {
            first: 1,
            inner: Inner { a: 0.5, b: None },
            left_out: None,
            given: Some(2.0),
            last: true,
        };
        assert_eq!(
            field_names(&v),
            Some(vec!["first", "a", "b", "given", "last"])
        );
    }

    #[test]
    fn plain_values_and_sequences_have_no_names() {
        assert_eq!(field_names(&1.0), None);
        assert_eq!(field_names(&[1.0, 2.0]), None);
    }
}
