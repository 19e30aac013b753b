//! Parameter tables: every GI parameter is written once, as a [`Param`] in the folder of the
//! method that reads it (or here and in [`common`] for those several methods share), and
//! everything else is derived from its row: the request's validation with the field's full
//! path, `/v1/server`'s description, the OpenAPI bounds, both CLIs' `--gi-param`, the software
//! profile's defaults and the README's table.
//!
//! A method reads its parameters as a typed struct ([`read`]), deserialised from its table's
//! values; the struct and the table are tied by a test over the registry (a field the table
//! lacks, or a row the struct lacks, fails to deserialise).

use super::common::params as common;
use super::InvalidSetting;
pub use lightcast_protocol::Senders;
use lightcast_protocol::{GiMethod, GiParamInfo, GiParamKind, GiParams, Limits};
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

/// What values a parameter takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// A whole number within the range.
    Integer,
    /// A finite number within the range.
    Number,
    Boolean,
    /// One of these names.
    Choice(&'static [&'static str]),
}

/// A value a table can hold in a `const`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Default {
    Int(u32),
    Float(f64),
    Bool(bool),
    Name(&'static str),
    /// `null`: the parameter's documentation says what the server derives instead.
    Null,
}

impl Default {
    pub fn json(self) -> Value {
        match self {
            Self::Int(v) => v.into(),
            Self::Float(v) => v.into(),
            Self::Bool(v) => v.into(),
            Self::Name(v) => v.into(),
            Self::Null => Value::Null,
        }
    }
}

/// One row of a method's parameter table: a field of `render.gi`.
#[derive(Clone, Copy, Debug)]
pub struct Param {
    /// The field's name in `render.gi` (its wire name; `--gi-param NAME=…`).
    pub name: &'static str,
    pub kind: Kind,
    /// Whether `null` is accepted (what the server does then is in `doc`).
    pub nullable: bool,
    pub default: Default,
    /// The default of the software profile (CPU adapters, see `service::defaults`), where it
    /// differs.
    pub software: Option<Default>,
    /// Smallest value (numbers).
    pub min: f64,
    /// Largest value any server accepts (numbers): the renderer's own limit.
    pub max: f64,
    /// `min` itself is outside the range.
    pub min_exclusive: bool,
    /// `max` itself is outside the range.
    pub max_exclusive: bool,
    /// This server's largest value where the operator configures it (within `max`).
    pub limit: Option<&'static super::limits::GiLimit>,
    /// The unit of a number, for people (`texels`, `scene units`); empty for none.
    pub unit: &'static str,
    pub doc: &'static str,
}

impl Param {
    const fn new(name: &'static str, kind: Kind, default: Default, doc: &'static str) -> Self {
        Self {
            name,
            kind,
            nullable: false,
            default,
            software: None,
            min: f64::NEG_INFINITY,
            max: f64::INFINITY,
            min_exclusive: false,
            max_exclusive: false,
            limit: None,
            unit: "",
            doc,
        }
    }

    /// A whole number in `min..=max`.
    pub const fn integer(
        name: &'static str,
        default: u32,
        (min, max): (u32, u32),
        doc: &'static str,
    ) -> Self {
        let mut p = Self::new(name, Kind::Integer, Default::Int(default), doc);
        p.min = min as f64;
        p.max = max as f64;
        p
    }

    /// A number in `min..=max`.
    pub const fn number(
        name: &'static str,
        default: f64,
        (min, max): (f64, f64),
        doc: &'static str,
    ) -> Self {
        let mut p = Self::new(name, Kind::Number, Default::Float(default), doc);
        p.min = min;
        p.max = max;
        p
    }

    /// A number or `null` (its default), in `min..=max`.
    pub const fn optional_number(
        name: &'static str,
        (min, max): (f64, f64),
        doc: &'static str,
    ) -> Self {
        let mut p = Self::number(name, 0.0, (min, max), doc);
        p.default = Default::Null;
        p.nullable = true;
        p
    }

    pub const fn boolean(name: &'static str, default: bool, doc: &'static str) -> Self {
        Self::new(name, Kind::Boolean, Default::Bool(default), doc)
    }

    /// One of `choices`.
    pub const fn choice(
        name: &'static str,
        default: &'static str,
        choices: &'static [&'static str],
        doc: &'static str,
    ) -> Self {
        Self::new(name, Kind::Choice(choices), Default::Name(default), doc)
    }

    /// `null` accepted, and the default.
    pub const fn or_null(mut self) -> Self {
        self.nullable = true;
        self.default = Default::Null;
        self
    }

    /// The software profile's default.
    pub const fn software(mut self, value: Default) -> Self {
        self.software = Some(value);
        self
    }

    /// The range is `(min, max]`.
    pub const fn above_min(mut self) -> Self {
        self.min_exclusive = true;
        self
    }

    /// The range is `[min, max)`.
    pub const fn below_max(mut self) -> Self {
        self.max_exclusive = true;
        self
    }

    /// This server's largest value, from its limits.
    pub const fn limit(mut self, limit: &'static super::limits::GiLimit) -> Self {
        self.limit = Some(limit);
        self
    }

    pub const fn unit(mut self, unit: &'static str) -> Self {
        self.unit = unit;
        self
    }

    /// The software profile's default (the default where the table gives none).
    pub fn software_default(&self) -> Value {
        self.software.unwrap_or(self.default).json()
    }

    /// The largest value on a server with `limits` (the renderer's own without).
    pub fn max_on(&self, limits: Option<&Limits>) -> f64 {
        match (self.limit, limits) {
            (Some(limit), Some(limits)) => (limit.of(limits) as f64).min(self.max),
            _ => self.max,
        }
    }

    /// Whether the parameter is a number with a range.
    fn ranged(&self) -> bool {
        matches!(self.kind, Kind::Integer | Kind::Number)
    }

    /// Checks `value`'s type and, with `range`, that it is within the range on a server with
    /// `limits` (the renderer's own range without).
    pub fn check(&self, value: &Value, range: bool, limits: Option<&Limits>) -> Result<(), String> {
        if value.is_null() {
            return if self.nullable {
                Ok(())
            } else {
                Err(format!("must be {}, not null", self.kind_words()))
            };
        }
        let number = match (self.kind, value) {
            (Kind::Integer, Value::Number(n))
                if n.as_u64().is_some_and(|v| v <= u32::MAX as u64) =>
            {
                n.as_f64()
            }
            (Kind::Number, Value::Number(n)) => n.as_f64(),
            (Kind::Boolean, Value::Bool(_)) => None,
            (Kind::Choice(choices), Value::String(s)) => {
                return if choices.contains(&s.as_str()) {
                    Ok(())
                } else {
                    Err(format!("{s:?} is not one of {}", choices.join(", ")))
                };
            }
            _ => return Err(format!("must be {}, not {value}", self.kind_words())),
        };
        let (Some(v), true) = (number, range) else {
            return Ok(());
        };
        let max = self.max_on(limits);
        let above = if self.max_exclusive {
            v >= max
        } else {
            v > max
        };
        let below = if self.min_exclusive {
            v <= self.min
        } else {
            v < self.min
        };
        if below || above {
            let server = if limits.is_some() {
                "this server's "
            } else {
                ""
            };
            return Err(format!(
                "{v} is outside {server}range {}",
                self.range_words(max)
            ));
        }
        Ok(())
    }

    /// `[min, max]` with its open ends.
    fn range_words(&self, max: f64) -> String {
        let start = if self.min_exclusive { "(" } else { "[" };
        let end = if self.max_exclusive || !max.is_finite() {
            ")"
        } else {
            "]"
        };
        let max = if max.is_finite() {
            max.to_string()
        } else {
            "∞".into()
        };
        format!("{start}{}, {max}{end}", self.min)
    }

    fn kind_words(&self) -> String {
        let what = match self.kind {
            Kind::Integer => "a whole number",
            Kind::Number => "a number",
            Kind::Boolean => "true or false",
            Kind::Choice(_) => "one of its names (a string)",
        };
        if self.nullable {
            format!("{what} or null")
        } else {
            what.to_string()
        }
    }

    /// The value `gi` gives the parameter, else its default.
    pub fn value<'a>(&self, gi: &'a GiParams) -> std::borrow::Cow<'a, Value> {
        gi.get(self.name)
            .map(std::borrow::Cow::Borrowed)
            .unwrap_or_else(|| std::borrow::Cow::Owned(self.default.json()))
    }

    /// An integer's value in `gi`, its default where `gi` has none or not a whole number
    /// (requests are checked before anything reads them; this is for estimates).
    pub fn u32(&self, gi: &GiParams) -> u32 {
        let fallback = match self.default {
            Default::Int(v) => v,
            _ => 0,
        };
        self.value(gi)
            .as_u64()
            .and_then(|v| u32::try_from(v).ok())
            .unwrap_or(fallback)
    }

    /// A boolean's value in `gi` (as [`Param::u32`]).
    pub fn bool(&self, gi: &GiParams) -> bool {
        self.value(gi)
            .as_bool()
            .unwrap_or(self.default == Default::Bool(true))
    }

    /// `/v1/server`'s description of the parameter on a server with `limits`.
    pub fn info(&self, limits: &Limits) -> GiParamInfo {
        let kind = match self.kind {
            Kind::Integer => GiParamKind::Integer,
            Kind::Number if self.nullable => GiParamKind::OptionalNumber,
            Kind::Number => GiParamKind::Number,
            Kind::Boolean => GiParamKind::Boolean,
            Kind::Choice(_) => GiParamKind::Choice,
        };
        let bound = |v: f64| (self.ranged() && v.is_finite()).then_some(v);
        GiParamInfo {
            name: self.name.into(),
            kind,
            default: self.default.json(),
            min: bound(self.min),
            max: bound(self.max_on(Some(limits))),
            min_exclusive: self.ranged() && self.min_exclusive,
            max_exclusive: self.ranged() && self.max_exclusive,
            choices: match self.kind {
                Kind::Choice(c) => c.iter().map(|c| c.to_string()).collect(),
                _ => Vec::new(),
            },
            unit: (!self.unit.is_empty()).then(|| self.unit.to_string()),
            description: self.doc.into(),
        }
    }
}

/// One method's table and what `/v1/server` says of it.
#[derive(Debug)]
pub struct MethodTable {
    pub method: GiMethod,
    /// One line for people, naming the paper and equations.
    pub summary: &'static str,
    /// Frames refine while nothing changes.
    pub progressive: bool,
    /// The parameters the method reads, besides the frame's ([`frame_params`]).
    pub params: &'static [&'static Param],
    /// The debug views the method draws besides `final` (see [`super::views`]).
    pub views: &'static [&'static super::views::DebugView],
    /// What the tests that run every method (frame memory, scale invariance) need of it.
    pub testing: Testing,
    /// The light transport a frame with these parameters models: how the light a surface
    /// receives straight from a light leaves it towards the surfaces it lights. A comparison
    /// also measures the method against a reference that models the same (see
    /// [`super::reference_senders`]).
    pub senders: fn(&GiParams) -> Senders,
}

/// A method's part in the tests that run every registered method.
#[derive(Debug)]
pub struct Testing {
    /// A small setting for a scene with `facts`: a frame of about 100×70 pixels of the
    /// Cornell box in well under a second on lavapipe, through every pass of the method.
    /// Lengths in it are relative to the scene (so a scaled scene gets a scaled setting).
    pub small: fn(&super::common::scene_facts::SceneFacts) -> GiParams,
    /// Relative mean absolute difference allowed between frames of the Cornell box scaled by
    /// 0.01 or 1000 and unscaled (HDR image and indirect buffer; radiance does not depend on
    /// the length unit, so what differs comes from rounded coordinates); the method's table
    /// says why this much.
    pub scale_tolerance: f32,
    /// Whether a power-of-two scale, exact in floating point, gives the very same pixels
    /// (no length constant and nothing derived by rounding from lengths).
    pub exact_at_powers_of_two: bool,
}

/// The tolerance of [`Testing::scale_tolerance`] for a method with no randomness that depends
/// on a rounded coordinate: measured on lavapipe, at most 0.05 % for every such method and
/// buffer; before ε_p of eq. 6 and the distance floors were made relative, LightSkin's
/// indirect buffer was off by 2.9 % (×1000: ε_p·A_l outweighed the form factors) and 17 %
/// (×0.01: the 1 cm floors), so 0.5 % separates the two with room for drivers.
pub const SCALE_TOLERANCE: f32 = 0.005;

/// The method's parameters as `T`: each of `table`'s, from `gi` or its default, checked
/// against its type and the renderer's range (the service has checked this server's range).
pub fn read<T: DeserializeOwned>(table: &[&Param], gi: &GiParams) -> Result<T, InvalidSetting> {
    read_for(table, table, gi)
}

/// As [`read`] for a struct two methods share (`lightskin`'s and `brsm`'s): the rows of
/// `table` that the frame's method reads (`own`) from `gi`, the others at their defaults.
pub fn read_for<T: DeserializeOwned>(
    table: &[&Param],
    own: &[&Param],
    gi: &GiParams,
) -> Result<T, InvalidSetting> {
    let mut values = Map::new();
    for p in table {
        let value = if own.iter().any(|o| o.name == p.name) {
            p.value(gi)
        } else {
            std::borrow::Cow::Owned(p.default.json())
        };
        p.check(&value, true, None)
            .map_err(|reason| InvalidSetting::new(p.name, reason))?;
        values.insert(p.name.to_string(), value.into_owned());
    }
    serde_json::from_value(Value::Object(values)).map_err(|e| {
        InvalidSetting::new(
            "method",
            format!("{}'s parameters do not match its table: {e}", gi.method),
        )
    })
}

/// The parameters of every frame, whatever its method: the renderer's own.
pub fn frame_params(method: GiMethod) -> Vec<&'static Param> {
    let mut params = vec![&common::GLOSSY_EXPONENT];
    if super::entry(method).1.downscales {
        params.push(&common::INDIRECT_DOWNSCALE);
    }
    params
}

/// Every parameter `method` reads: its table's, then the frame's.
pub fn of(method: GiMethod) -> Vec<&'static Param> {
    let table = super::table(method);
    let mut params: Vec<&'static Param> = table.params.to_vec();
    params.extend(frame_params(method));
    params
}

/// Every parameter of every registered method, each once, in registry order.
pub fn all() -> Vec<&'static Param> {
    let mut all: Vec<&'static Param> = Vec::new();
    for method in super::methods() {
        for p in of(method) {
            if !all.iter().any(|q| q.name == p.name) {
                all.push(p);
            }
        }
    }
    all
}

/// `gi` with every parameter its method reads, at its value or default (and no other), a
/// number written as one (`80` as `80.0`): what a report says the frame was rendered with,
/// and a key equal requests share.
pub fn resolved(gi: &GiParams) -> GiParams {
    let mut out = GiParams::new(gi.method);
    for p in of(gi.method) {
        let value = p.value(gi).into_owned();
        let value = match (p.kind, value.as_f64()) {
            (Kind::Number, Some(v)) => v.into(),
            _ => value,
        };
        out.set(p.name, value);
    }
    out
}

/// The row of parameter `name`, if a method has it.
pub fn find(name: &str) -> Option<&'static Param> {
    all().into_iter().find(|p| p.name == name)
}

/// Why a request's `gi` is refused: the field under `gi` and the reason.
#[derive(Debug, PartialEq)]
pub struct Refusal {
    pub field: String,
    pub reason: String,
}

/// Checks a request's GI parameters on a server with `limits`: every field must be a
/// parameter of some method and of its type (so a misspelt name is an error, not a silently
/// ignored value), and the frame's method's own must be within this server's range; the
/// other methods' are kept for when the client switches to them.
pub fn check_request(gi: &GiParams, limits: &Limits) -> Result<(), Refusal> {
    super::check_method(gi.method).map_err(|e| Refusal {
        field: e.field.to_string(),
        reason: e.reason,
    })?;
    let own = of(gi.method);
    for (name, value) in &gi.values {
        let Some(param) = find(name) else {
            return Err(Refusal {
                field: name.clone(),
                reason: format!(
                    "unknown GI parameter; {} reads {}",
                    gi.method,
                    own.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
                ),
            });
        };
        let range = own.iter().any(|p| p.name == param.name);
        param
            .check(value, range, Some(limits))
            .map_err(|reason| Refusal {
                field: name.clone(),
                reason,
            })?;
    }
    Ok(())
}

/// Every parameter at its default (`software`: the software profile's), as `render.gi`'s
/// fields besides `method`.
pub fn defaults(software: bool) -> std::collections::BTreeMap<String, Value> {
    all()
        .into_iter()
        .map(|p| {
            let d = if software {
                p.software_default()
            } else {
                p.default.json()
            };
            (p.name.to_string(), d)
        })
        .collect()
}

/// The README's parameter table, derived from the tables (a test keeps the README's copy).
pub fn markdown_table() -> String {
    let mut s = String::from(
        "| parameter | methods | type | default | software default | range | unit | meaning |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for p in all() {
        let methods: Vec<String> = super::methods()
            .filter(|&m| of(m).iter().any(|q| q.name == p.name))
            .map(|m| m.to_string())
            .collect();
        let kind = match p.kind {
            Kind::Integer => "integer".to_string(),
            Kind::Number => "number".to_string(),
            Kind::Boolean => "boolean".to_string(),
            Kind::Choice(c) => c.join(" \\| "),
        };
        let kind = if p.nullable {
            format!("{kind} or null")
        } else {
            kind
        };
        let show = |d: Default| match d.json() {
            Value::String(s) => s,
            v => v.to_string(),
        };
        let range = if p.ranged() {
            let server = if p.limit.is_some() {
                " (server limit)"
            } else {
                ""
            };
            format!("{}{server}", p.range_words(p.max))
        } else {
            String::new()
        };
        s += &format!(
            "| `{}` | {} | {kind} | {} | {} | {range} | {} | {} |\n",
            p.name,
            methods.join(", "),
            show(p.default),
            p.software.map(show).unwrap_or_default(),
            p.unit,
            p.doc.replace('|', "\\|"),
        );
    }
    s
}

/// The OpenAPI schema of `render.gi`: `method` and every parameter with its type, default and
/// the range any server accepts (a server's own limits are in `/v1/server`).
pub fn openapi_properties() -> Map<String, Value> {
    let mut props = Map::new();
    for p in all() {
        let mut schema = Map::new();
        let ty = match p.kind {
            Kind::Integer => "integer",
            Kind::Number => "number",
            Kind::Boolean => "boolean",
            Kind::Choice(choices) => {
                schema.insert("enum".into(), choices.to_vec().into());
                "string"
            }
        };
        schema.insert(
            "type".into(),
            if p.nullable {
                Value::from(vec![ty, "null"])
            } else {
                ty.into()
            },
        );
        // Whole numbers are written as such (`16`, not `16.0`).
        let bound = |v: f64| -> Value {
            if p.kind == Kind::Integer {
                (v as u64).into()
            } else {
                v.into()
            }
        };
        if p.ranged() {
            if p.min.is_finite() {
                let key = if p.min_exclusive {
                    "exclusiveMinimum"
                } else {
                    "minimum"
                };
                schema.insert(key.into(), bound(p.min));
            }
            if p.max.is_finite() {
                let key = if p.max_exclusive {
                    "exclusiveMaximum"
                } else {
                    "maximum"
                };
                schema.insert(key.into(), bound(p.max));
            }
        }
        if p.kind == Kind::Integer {
            schema.insert("format".into(), "int32".into());
        }
        schema.insert("default".into(), p.default.json());
        let unit = if p.unit.is_empty() {
            String::new()
        } else {
            format!(" Unit: {}.", p.unit)
        };
        schema.insert("description".into(), format!("{}.{unit}", p.doc).into());
        props.insert(p.name.to_string(), Value::Object(schema));
    }
    props
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every method's struct reads its table's defaults: a row the struct lacks or a field
    /// the table lacks fails here. A name means one parameter wherever it appears.
    #[test]
    fn every_table_matches_its_method_and_names_each_parameter_once() {
        for method in super::super::methods() {
            (super::super::entry(method).1.check_table)(&GiParams::new(method))
                .unwrap_or_else(|e| panic!("{method}: {e}"));
            for p in of(method) {
                let first = find(p.name).expect("listed");
                assert!(
                    std::ptr::eq(first, p),
                    "{method}: {} is defined twice",
                    p.name
                );
                assert!(!p.doc.is_empty(), "{}", p.name);
                p.check(&p.default.json(), true, None)
                    .unwrap_or_else(|e| panic!("{}'s default: {e}", p.name));
                if let Some(s) = p.software {
                    p.check(&s.json(), true, None)
                        .unwrap_or_else(|e| panic!("{}'s software default: {e}", p.name));
                }
            }
        }
    }

    /// The defaults of the parameters the protocol's flat `GiParams` had before the tables
    /// are still its (the paper's evaluation settings) and the software profile's measured
    /// ones; `jitter` and `uniform_importance` were the renderer's fixed 0.5 and false.
    /// Parameters added since (a new method's) are held by their own tables.
    #[test]
    fn the_defaults_are_the_papers_and_the_measured_software_ones() {
        let gpu = serde_json::json!({
            "rsm_size": 1024, "view_samples": 512, "val_count": 8192, "defensive": 0.3,
            "occlusion": true, "glossy_exponent": null, "cache_distance": null,
            "cache_angle": null, "bounces": 1, "emitters": null, "spp": 4, "vpl_count": 1024,
            "cluster_count": 30, "kmeans_iterations": 4, "cluster_position_weight": 0.7,
            "cluster_normal_weight": 0.3, "interleave": 8, "blur_distance": 0.1,
            "blur_normal": 0.8, "visibility": "cssm", "paraboloid_size": 256,
            "fourier_terms": 4, "shadow_light": 0, "indirect_downscale": 1,
            "surfel_count": 32768, "surfel_cache_spacing": null, "surfel_links": 128,
            "sh_bands": 3, "jitter": 0.5, "uniform_importance": false
        });
        let released = |all: serde_json::Value| -> serde_json::Value {
            let keys = gpu.as_object().expect("an object");
            all.as_object()
                .expect("an object")
                .iter()
                .filter(|(k, _)| keys.contains_key(*k))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect()
        };
        assert_eq!(
            released(serde_json::to_value(defaults(false)).expect("json")),
            gpu
        );
        let mut software = gpu.clone();
        for (name, value) in [
            ("rsm_size", 112),
            ("view_samples", 32),
            ("val_count", 512),
            ("indirect_downscale", 2),
            ("surfel_count", 8192),
            ("surfel_links", 64),
            ("spp", 1),
            ("interleave", 4),
            ("paraboloid_size", 64),
        ] {
            software[name] = value.into();
        }
        assert_eq!(
            released(serde_json::to_value(defaults(true)).expect("json")),
            software
        );
        assert_eq!(GiMethod::default(), crate::gi::lightskin::BRSM);
    }

    /// The README's parameter table is the tables' (`lightcast-server gi-params` prints it).
    #[test]
    fn the_readme_lists_the_parameters_of_the_tables() {
        let readme = include_str!("../../../README.md");
        let (begin, end) = ("<!-- gi-params:begin -->\n", "<!-- gi-params:end -->");
        let start = readme.find(begin).expect("the README marks its table") + begin.len();
        let len = readme[start..].find(end).expect("and its end");
        let table = markdown_table();
        assert!(
            readme[start..start + len] == table,
            "the README's GI parameter table is stale; replace it with \
             `lightcast-server gi-params`:\n{table}"
        );
    }

    #[test]
    fn requests_are_checked_by_type_everywhere_and_by_range_for_their_method() {
        let limits = crate::gi::limits::default_limits();
        let ok = GiParams::new(crate::gi::lightskin::BRSM).with("rsm_size", 64);
        assert_eq!(check_request(&ok, &limits), Ok(()));
        let unknown = GiParams::new(crate::gi::lightskin::BRSM).with("rsm_sise", 64);
        let e = check_request(&unknown, &limits).expect_err("unknown");
        assert_eq!(e.field, "rsm_sise");
        assert!(e.reason.contains("rsm_size"), "{}", e.reason);
        // A ranged integer parameter of some method that another method does not read: type
        // checked for both, range checked for its own only.
        let (owner, param, other) = crate::gi::methods()
            .flat_map(|m| of(m).into_iter().map(move |p| (m, p)))
            .filter(|(_, p)| matches!(p.kind, Kind::Integer) && p.max.is_finite())
            .find_map(|(m, p)| {
                let other = crate::gi::methods().find(|&o| !of(o).iter().any(|q| q.name == p.name));
                other.map(|o| (m, p, o))
            })
            .expect("some method has a parameter another lacks");
        let typed = GiParams::new(other).with(param.name, "many");
        assert_eq!(
            check_request(&typed, &limits).expect_err("type").field,
            param.name
        );
        let beyond = param.max as u64 + 1;
        assert_eq!(
            check_request(&GiParams::new(other).with(param.name, beyond), &limits),
            Ok(()),
            "another method's range"
        );
        assert!(check_request(&GiParams::new(owner).with(param.name, beyond), &limits).is_err());
        let big = GiParams::new(crate::gi::lightskin::BRSM).with(
            "rsm_size",
            crate::gi::common::limits::MAX_RSM_SIZE.of(&limits) + 1,
        );
        let e = check_request(&big, &limits).expect_err("beyond the server's limit");
        assert!(e.reason.contains("this server's"), "{}", e.reason);
        let unknown = GiParams::new(GiMethod::new("fancy"));
        let e = check_request(&unknown, &limits).expect_err("no such method");
        assert_eq!(e.field, "method");
        for method in crate::gi::methods() {
            assert!(e.reason.contains(method.name()), "{}", e.reason);
        }
        let float = GiParams::new(crate::gi::lightskin::BRSM).with("rsm_size", 64.5);
        assert!(check_request(&float, &limits).is_err());
        let null = GiParams::new(crate::gi::reference::REFERENCE).with("spp", Value::Null);
        // Renderer-side reads check the renderer's range of the method's own parameters.
        let low = GiParams::new(crate::gi::lightskin::BRSM).with("val_count", 0);
        let e = crate::gi::lightskin::Settings::of(&low).expect_err("out of range");
        assert_eq!(e.field, "val_count");
        let lightskin = GiParams::new(crate::gi::lightskin::LIGHTSKIN).with("val_count", 0);
        crate::gi::lightskin::Settings::of(&lightskin).expect("brsm's parameter is not read");
        let angle = GiParams::new(crate::gi::lightskin::LIGHTSKIN).with("cache_angle", 120);
        let e = crate::gi::lightskin::Settings::of(&angle).expect_err("out of range");
        assert_eq!(e.field, "cache_angle");
        assert!(check_request(&null, &limits).is_err());
    }
}
