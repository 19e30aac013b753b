//! Names the server's registry owns (GI methods, debug views): the protocol checks only their
//! spelling, so a method or view added on the server needs no protocol change. Each is held
//! inline, so it is `Copy` and a server module can name one in a `const`.

/// Declares a name type: 1 to `MAX_LEN` bytes of `a-z`, `0-9` and `$sep`, with `const fn
/// new` (a bad name fails to compile in a `const`), `parse`, `name`, `Display`, `Debug`,
/// `FromStr` and serde as a string.
macro_rules! inline_name {
    ($(#[$doc:meta])* $name:ident, sep = $sep:literal, noun = $noun:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, PartialEq, Eq, Hash)]
        pub struct $name {
            len: u8,
            bytes: [u8; $name::MAX_LEN],
        }

        impl $name {
            /// Longest name.
            pub const MAX_LEN: usize = 31;

            /// The regular expression of a name (for schemas).
            pub const PATTERN: &'static str = concat!("^[a-z0-9", $sep, "]{1,31}$");

            /// The name `name`; a name that is not one fails to compile in a `const`.
            pub const fn new(name: &str) -> Self {
                match Self::check(name) {
                    Ok(v) => v,
                    Err(()) => panic!(concat!("a ", $noun, "'s name is 1 to 31 of a-z, 0-9 and ", $sep)),
                }
            }

            /// The name `name`, if it is spelt as one (whether the server has it is the
            /// server's to say).
            pub fn parse(name: &str) -> Result<Self, String> {
                Self::check(name).map_err(|()| {
                    format!(
                        concat!("{:?} is not a ", $noun, "'s name (1 to {} of a-z, 0-9 and ", $sep, ")"),
                        name,
                        Self::MAX_LEN
                    )
                })
            }

            const fn check(name: &str) -> Result<Self, ()> {
                let b = name.as_bytes();
                if b.is_empty() || b.len() > Self::MAX_LEN {
                    return Err(());
                }
                let sep = $sep.as_bytes()[0];
                let mut bytes = [0u8; Self::MAX_LEN];
                let mut i = 0;
                while i < b.len() {
                    if !(b[i].is_ascii_lowercase() || b[i].is_ascii_digit() || b[i] == sep) {
                        return Err(());
                    }
                    bytes[i] = b[i];
                    i += 1;
                }
                Ok(Self {
                    len: b.len() as u8,
                    bytes,
                })
            }

            /// The name requests use.
            pub fn name(&self) -> &str {
                // Only ASCII is ever stored (`check`).
                std::str::from_utf8(&self.bytes[..usize::from(self.len)]).unwrap_or_default()
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::fmt::Debug for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::str::FromStr for $name {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                Self::parse(s)
            }
        }

        impl serde::Serialize for $name {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.serialize_str(self.name())
            }
        }

        impl<'de> serde::Deserialize<'de> for $name {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                let name = std::borrow::Cow::<'de, str>::deserialize(d)?;
                Self::parse(&name).map_err(serde::de::Error::custom)
            }
        }

        impl utoipa::ToSchema for $name {
            fn name() -> std::borrow::Cow<'static, str> {
                stringify!($name).into()
            }
        }
    };
}

inline_name!(
    /// How indirect light is computed: a GI method's name (`brsm`, `reference`), one of those
    /// the server lists in `/v1/server`'s `gi_methods`: 1 to [`GiMethod::MAX_LEN`] lowercase
    /// ASCII letters, digits and underscores. The server refuses one it does not have, naming
    /// `render.gi.method`.
    GiMethod,
    sep = "_",
    noun = "GI method"
);

inline_name!(
    /// Which image a frame shows: `final` (the tone-mapped frame) or a debug view of the
    /// frame's GI method, one of those `/v1/server`'s `gi_methods` lists under `views`: 1 to
    /// [`View::MAX_LEN`] lowercase ASCII letters, digits and hyphens. The server refuses a view
    /// the frame's method does not draw, naming `render.view`.
    View,
    sep = "-",
    noun = "view"
);

impl Default for GiMethod {
    /// `brsm`, the server's default method (seed 004's, and the one its defaults describe).
    fn default() -> Self {
        Self::new("brsm")
    }
}

impl View {
    /// The tone-mapped frame, which every method shows.
    pub const FINAL: Self = Self::new("final");
}

impl Default for View {
    fn default() -> Self {
        Self::FINAL
    }
}

/// A string schema with `pattern` and `description` (the server's `openapi` command adds the
/// registry's names as an `enum`).
fn name_schema(
    pattern: &str,
    description: &str,
) -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
    use utoipa::openapi::schema::{ObjectBuilder, Type};
    ObjectBuilder::new()
        .schema_type(Type::String)
        .pattern(Some(pattern))
        .description(Some(description))
        .into()
}

impl utoipa::PartialSchema for GiMethod {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        name_schema(
            Self::PATTERN,
            "A GI method's name, one of `/v1/server`'s `gi_methods` (how indirect light is \
             computed).",
        )
    }
}

impl utoipa::PartialSchema for View {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        name_schema(
            Self::PATTERN,
            "Which image a frame shows: `final`, or one of the debug views `/v1/server` lists \
             under the frame's GI method (`gi_methods[].views`).",
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_checked_by_their_alphabet() {
        assert_eq!(GiMethod::parse("rsm_gather").unwrap().name(), "rsm_gather");
        assert!(GiMethod::parse("rsm-gather").is_err());
        assert_eq!(View::parse("rsm-flux").unwrap().name(), "rsm-flux");
        assert!(View::parse("rsm_flux").is_err());
        assert!(View::parse("").is_err() && View::parse(&"a".repeat(32)).is_err());
        assert!(View::parse("Final").is_err());
        let v: View = serde_json::from_str("\"cache-sh\"").unwrap();
        assert_eq!(serde_json::to_string(&v).unwrap(), "\"cache-sh\"");
        assert!(serde_json::from_str::<View>("\"no view\"").is_err());
        assert_eq!(View::default(), View::FINAL);
    }
}
