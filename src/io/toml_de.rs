//! TOML read into calsim's types, every array held to the length its key takes. serde's `[T; N]`
//! (and tuple) reads N values and leaves refusing any more to the deserializer; toml's text
//! deserializer does not refuse them (its `Value` does, in words that say "fewer elements"), so
//! `x_mm = [1, 2, 3]` read into a `[f64; 2]` would silently be `[1, 2]`. Every TOML input
//! calsim reads into its own types goes through [`from_str`], [`from_str_keyed`] or
//! [`from_table`] (a test of the module graph keeps it so), which wrap the deserializer in
//! [`Exact`]: a sequence a visitor stops reading before its end is refused as `invalid length 3,
//! expected an array of length 2`, the words serde uses for an array that is too short.

use serde::de::{self, DeserializeSeed, Deserializer, EnumAccess, IgnoredAny, MapAccess, SeqAccess, VariantAccess, Visitor};
use std::fmt;

/// `text` read into `T`; an error keeps the span toml gives it (for [`super::toml_position`]).
pub fn from_str<'a, T: de::Deserialize<'a>>(text: &'a str) -> Result<T, toml::de::Error> {
    T::deserialize(Exact(toml::Deserializer::parse(text)?))
}

/// `text` read into `T`; an error as (where, what): where is the line (`line 5, [study]
/// repetitions`) of text that is not TOML, else the path of the key (`points.x_mm`, `(file)` for
/// the file as a whole).
pub fn from_str_keyed<'a, T: de::Deserialize<'a>>(text: &'a str) -> Result<T, (String, String)> {
    let de = toml::Deserializer::parse(text).map_err(|e| (super::toml_position(text, e.span()), e.message().to_string()))?;
    serde_path_to_error::deserialize(Exact(de)).map_err(keyed)
}

/// A TOML table (a scenario's, its defaults filled in) read into `T`; an error as (the path of the
/// key, what), as for [`from_str_keyed`].
pub fn from_table<T: de::DeserializeOwned>(t: toml::Table) -> Result<T, (String, String)> {
    serde_path_to_error::deserialize(Exact(toml::Value::Table(t))).map_err(keyed)
}

fn keyed(e: serde_path_to_error::Error<toml::de::Error>) -> (String, String) {
    let key = e.path().to_string();
    let key = if key == "." { "(file)".to_string() } else { key };
    (key, e.into_inner().message().to_string())
}

/// A deserializer whose every sequence is read to its end: what a visitor leaves unread (the
/// fourth value of a `[f64; 3]`) is an error. Everything else is the wrapped deserializer's own.
struct Exact<D>(D);

/// A visitor that hands the values it is given on as [`Exact`] deserializers.
struct Nested<V>(V);

/// A seed deserialized through [`Exact`].
struct Seed<S>(S);

/// The elements of a sequence, as [`Exact`] deserializers, and how many the visitor took.
struct Elements<A> {
    access: A,
    taken: usize,
}

/// The values of a table, as [`Exact`] deserializers.
struct Entries<A>(A);

/// An enum's variant, its content as an [`Exact`] deserializer.
struct Variant<A>(A);

macro_rules! forward_deserialize {
    ($($method:ident($($arg:ident: $ty:ty),*);)*) => {
        $(fn $method<V: Visitor<'de>>(self, $($arg: $ty,)* visitor: V) -> Result<V::Value, D::Error> {
            self.0.$method($($arg,)* Nested(visitor))
        })*
    };
}

impl<'de, D: Deserializer<'de>> Deserializer<'de> for Exact<D> {
    type Error = D::Error;

    forward_deserialize! {
        deserialize_any(); deserialize_bool();
        deserialize_i8(); deserialize_i16(); deserialize_i32(); deserialize_i64(); deserialize_i128();
        deserialize_u8(); deserialize_u16(); deserialize_u32(); deserialize_u64(); deserialize_u128();
        deserialize_f32(); deserialize_f64(); deserialize_char(); deserialize_str(); deserialize_string();
        deserialize_bytes(); deserialize_byte_buf(); deserialize_option(); deserialize_unit();
        deserialize_unit_struct(name: &'static str); deserialize_newtype_struct(name: &'static str);
        deserialize_seq(); deserialize_tuple(len: usize); deserialize_tuple_struct(name: &'static str, len: usize);
        deserialize_map(); deserialize_struct(name: &'static str, fields: &'static [&'static str]);
        deserialize_enum(name: &'static str, variants: &'static [&'static str]);
        deserialize_identifier(); deserialize_ignored_any();
    }

    fn is_human_readable(&self) -> bool {
        self.0.is_human_readable()
    }
}

macro_rules! forward_visit {
    ($($method:ident($ty:ty);)*) => {
        $(fn $method<E: de::Error>(self, v: $ty) -> Result<Self::Value, E> {
            self.0.$method(v)
        })*
    };
}

impl<'de, V: Visitor<'de>> Visitor<'de> for Nested<V> {
    type Value = V::Value;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        self.0.expecting(f)
    }

    forward_visit! {
        visit_bool(bool); visit_i8(i8); visit_i16(i16); visit_i32(i32); visit_i64(i64); visit_i128(i128);
        visit_u8(u8); visit_u16(u16); visit_u32(u32); visit_u64(u64); visit_u128(u128);
        visit_f32(f32); visit_f64(f64); visit_char(char); visit_str(&str); visit_borrowed_str(&'de str);
        visit_string(String); visit_bytes(&[u8]); visit_borrowed_bytes(&'de [u8]); visit_byte_buf(Vec<u8>);
    }

    fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
        self.0.visit_none()
    }

    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        self.0.visit_unit()
    }

    fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        self.0.visit_some(Exact(d))
    }

    fn visit_newtype_struct<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        self.0.visit_newtype_struct(Exact(d))
    }

    /// The one check: a visitor that returns before the sequence's end (a fixed-length array, a
    /// tuple) was given more values than it takes.
    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        let mut elements = Elements { access: seq, taken: 0 };
        let value = self.0.visit_seq(&mut elements)?;
        let mut more = 0;
        while elements.access.next_element::<IgnoredAny>()?.is_some() {
            more += 1;
        }
        if more > 0 {
            let taken = elements.taken;
            return Err(de::Error::invalid_length(taken + more, &format!("an array of length {taken}").as_str()));
        }
        Ok(value)
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
        self.0.visit_map(Entries(map))
    }

    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<Self::Value, A::Error> {
        self.0.visit_enum(Variant(data))
    }
}

impl<'de, S: DeserializeSeed<'de>> DeserializeSeed<'de> for Seed<S> {
    type Value = S::Value;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        self.0.deserialize(Exact(d))
    }
}

impl<'de, A: SeqAccess<'de>> SeqAccess<'de> for Elements<A> {
    type Error = A::Error;

    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<Option<T::Value>, A::Error> {
        let next = self.access.next_element_seed(Seed(seed))?;
        self.taken += usize::from(next.is_some());
        Ok(next)
    }

    fn size_hint(&self) -> Option<usize> {
        self.access.size_hint()
    }
}

impl<'de, A: MapAccess<'de>> MapAccess<'de> for Entries<A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(&mut self, seed: K) -> Result<Option<K::Value>, A::Error> {
        self.0.next_key_seed(Seed(seed))
    }

    fn next_value_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<T::Value, A::Error> {
        self.0.next_value_seed(Seed(seed))
    }

    fn size_hint(&self) -> Option<usize> {
        self.0.size_hint()
    }
}

impl<'de, A: EnumAccess<'de>> EnumAccess<'de> for Variant<A> {
    type Error = A::Error;
    type Variant = Variant<A::Variant>;

    fn variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<(T::Value, Self::Variant), A::Error> {
        let (value, variant) = self.0.variant_seed(Seed(seed))?;
        Ok((value, Variant(variant)))
    }
}

impl<'de, A: VariantAccess<'de>> VariantAccess<'de> for Variant<A> {
    type Error = A::Error;

    fn unit_variant(self) -> Result<(), A::Error> {
        self.0.unit_variant()
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, A::Error> {
        self.0.newtype_variant_seed(Seed(seed))
    }

    fn tuple_variant<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, A::Error> {
        self.0.tuple_variant(len, Nested(visitor))
    }

    fn struct_variant<V: Visitor<'de>>(self, fields: &'static [&'static str], visitor: V) -> Result<V::Value, A::Error> {
        self.0.struct_variant(fields, Nested(visitor))
    }
}

#[cfg(test)]
mod tests {
    use super::{from_str, from_str_keyed, from_table};
    use serde::Deserialize;

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Inner {
        xs: Vec<[f64; 2]>,
        pair: Option<(u32, String)>,
    }

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Outer {
        point_mm: [f64; 3],
        #[serde(default)]
        inner: Vec<Inner>,
        kind: Kind,
    }

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(rename_all = "snake_case")]
    enum Kind {
        Plain,
        Ranged { range: [f64; 2] },
    }

    #[test]
    fn arrays_of_their_length_read_as_before() {
        let text = "point_mm = [1, 2.5, 3]\nkind = \"plain\"\n[[inner]]\nxs = [[1, 2], [3, 4], [5, 6]]\npair = [7, \"a\"]\n";
        let o: Outer = from_str(text).unwrap();
        assert_eq!(o, toml::from_str(text).unwrap(), "the same value as toml's own");
        assert_eq!(o.inner[0].xs.len(), 3, "a list takes any length");
        let ranged: Outer = from_str("point_mm = [0, 0, 0]\nkind = { ranged = { range = [1, 2] } }\n").unwrap();
        assert_eq!(ranged.kind, Kind::Ranged { range: [1.0, 2.0] });
    }

    #[test]
    fn a_longer_array_is_refused_at_any_depth_naming_its_line_or_key() {
        // toml's own reader takes the first three values: the hole this module closes.
        let long = "point_mm = [1, 2, 3, 4, 5]\nkind = \"plain\"\n";
        assert_eq!(toml::from_str::<Outer>(long).unwrap().point_mm, [1.0, 2.0, 3.0]);
        let e = from_str::<Outer>(long).unwrap_err();
        assert_eq!(e.message(), "invalid length 5, expected an array of length 3");
        assert_eq!(super::super::toml_position(long, e.span()), "line 1, point_mm");

        let nested = "point_mm = [1, 2, 3]\nkind = \"plain\"\n[[inner]]\nxs = [[1, 2], [3, 4, 9]]\n";
        assert_eq!(
            from_str_keyed::<Outer>(nested).unwrap_err(),
            ("inner[0].xs[1]".into(), "invalid length 3, expected an array of length 2".into())
        );
        let tuple = "point_mm = [1, 2, 3]\nkind = \"plain\"\n[[inner]]\nxs = []\npair = [7, \"a\", 8]\n";
        assert_eq!(from_str_keyed::<Outer>(tuple).unwrap_err().1, "invalid length 3, expected an array of length 2");
        let variant = "point_mm = [1, 2, 3]\nkind = { ranged = { range = [1, 2, 3] } }\n";
        assert_eq!(
            from_str_keyed::<Outer>(variant).unwrap_err(),
            ("kind.ranged.range".into(), "invalid length 3, expected an array of length 2".into())
        );
    }

    #[test]
    fn a_table_is_held_to_the_same_lengths_in_the_same_words() {
        let table = |text: &str| text.parse::<toml::Table>().unwrap();
        let long = table("point_mm = [1, 2, 3, 4]\nkind = \"plain\"\n");
        assert_eq!(from_table::<Outer>(long).unwrap_err(), ("point_mm".into(), "invalid length 4, expected an array of length 3".into()));
        let short = table("point_mm = [1, 2]\nkind = \"plain\"\n");
        assert_eq!(from_table::<Outer>(short).unwrap_err(), ("point_mm".into(), "invalid length 2, expected an array of length 3".into()));
        assert_eq!(from_table::<Outer>(table("kind = \"plain\"\n")).unwrap_err(), ("(file)".into(), "missing field `point_mm`".into()));
    }
}
