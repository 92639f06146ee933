//! The identifiable parameters as data: names in the paper's notation, units at the edges, and
//! pack/unpack between a [`RobotModel`] and a vector.
//!
//! Inside the vector every value is in calsim's internal units (mm, rad, rad/(N m)); [`Unit`]
//! converts to the units printed in the paper's Table 7 (mm, deg, mdeg/(N m)).

use std::fmt;

use nalgebra::DVector;

use super::model::{JOINTS, ModelError, RobotData, RobotModel};

/// Which number of a modified-DH row.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LinkParam {
    /// alpha_{i-1}.
    Alpha,
    /// a_{i-1}.
    A,
    /// beta_{i-1} (Hayati).
    Beta,
    /// theta_offs,i.
    ThetaOffset,
    /// d_i.
    D,
    /// c_i.
    Compliance,
}

/// Which number of the base transform (eq. 7).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BaseParam {
    /// x_0^W.
    X,
    /// y_0^W.
    Y,
    /// z_0^W.
    Z,
    /// alpha_0^W (about z).
    Alpha,
    /// beta_0^W (about y).
    Beta,
    /// gamma_0^W (about x).
    Gamma,
}

/// One parameter of the model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ParamId {
    /// A number of the modified-DH row of joint `joint` (1-based), i.e. of `T(joint-1, joint)`.
    Link {
        /// Joint number, 1..=6.
        joint: usize,
        /// Which number.
        kind: LinkParam,
    },
    /// A number of `world_from_base`.
    Base(BaseParam),
    /// A coordinate (0 = x, 1 = y, 2 = z) of the TCP in the flange frame.
    Tool(usize),
}

/// Unit a parameter is shown in at the edges (scenario files, tables, reports).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// Millimetres (also the internal unit).
    Mm,
    /// Degrees (internal: rad).
    Deg,
    /// Millidegrees per newton metre, as Table 7 prints compliance (internal: rad/(N m)).
    MdegPerNm,
}

impl Unit {
    /// Internal value to this unit.
    pub fn from_internal(self, v: f64) -> f64 {
        match self {
            Unit::Mm => v,
            Unit::Deg => v.to_degrees(),
            Unit::MdegPerNm => v.to_degrees() * 1e3,
        }
    }

    /// Value in this unit to the internal unit.
    pub fn to_internal(self, v: f64) -> f64 {
        match self {
            Unit::Mm => v,
            Unit::Deg => v.to_radians(),
            Unit::MdegPerNm => (v * 1e-3).to_radians(),
        }
    }

    /// Symbol for tables.
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Mm => "mm",
            Unit::Deg => "deg",
            Unit::MdegPerNm => "mdeg/(N m)",
        }
    }
}

const BASE_NAMES: [(&str, BaseParam); 6] = [
    ("x0W", BaseParam::X),
    ("y0W", BaseParam::Y),
    ("z0W", BaseParam::Z),
    ("alpha0W", BaseParam::Alpha),
    ("beta0W", BaseParam::Beta),
    ("gamma0W", BaseParam::Gamma),
];
const TOOL_NAMES: [&str; 3] = ["xT6", "yT6", "zT6"];

impl ParamId {
    /// Shorthand for a link parameter.
    pub const fn link(joint: usize, kind: LinkParam) -> Self {
        ParamId::Link { joint, kind }
    }

    /// The name in the paper's notation: `alpha1`, `a2`, `beta2`, `d4`, `theta_offs3`, `c5`, `x0W`, `xT6`.
    pub fn name(&self) -> String {
        match *self {
            ParamId::Link { joint, kind } => match kind {
                LinkParam::Alpha => format!("alpha{}", joint - 1),
                LinkParam::A => format!("a{}", joint - 1),
                LinkParam::Beta => format!("beta{}", joint - 1),
                LinkParam::ThetaOffset => format!("theta_offs{joint}"),
                LinkParam::D => format!("d{joint}"),
                LinkParam::Compliance => format!("c{joint}"),
            },
            ParamId::Base(b) => BASE_NAMES.iter().find(|(_, p)| *p == b).map(|(n, _)| n.to_string()).unwrap_or_default(),
            ParamId::Tool(k) => TOOL_NAMES[k].to_string(),
        }
    }

    /// Parses a name produced by [`ParamId::name`].
    pub fn parse(name: &str) -> Option<Self> {
        if let Some((_, b)) = BASE_NAMES.iter().find(|(n, _)| *n == name) {
            return Some(ParamId::Base(*b));
        }
        if let Some(k) = TOOL_NAMES.iter().position(|n| *n == name) {
            return Some(ParamId::Tool(k));
        }
        // Longest prefixes first: "alpha" before "a", "theta_offs" before nothing else.
        let table: [(&str, LinkParam, usize); 6] = [
            ("theta_offs", LinkParam::ThetaOffset, 0),
            ("alpha", LinkParam::Alpha, 1),
            ("beta", LinkParam::Beta, 1),
            ("a", LinkParam::A, 1),
            ("d", LinkParam::D, 0),
            ("c", LinkParam::Compliance, 0),
        ];
        for (prefix, kind, shift) in table {
            if let Some(rest) = name.strip_prefix(prefix) {
                let index: usize = rest.parse().ok()?;
                let joint = index + shift;
                return (1..=JOINTS).contains(&joint).then_some(ParamId::Link { joint, kind });
            }
        }
        None
    }

    /// The unit this parameter is shown in.
    pub fn unit(&self) -> Unit {
        match self {
            ParamId::Link { kind: LinkParam::A | LinkParam::D, .. } => Unit::Mm,
            ParamId::Link { kind: LinkParam::Compliance, .. } => Unit::MdegPerNm,
            ParamId::Link { .. } => Unit::Deg,
            ParamId::Base(BaseParam::X | BaseParam::Y | BaseParam::Z) => Unit::Mm,
            ParamId::Base(_) => Unit::Deg,
            ParamId::Tool(_) => Unit::Mm,
        }
    }

    /// The value in `data`, internal units.
    pub fn get(&self, data: &RobotData) -> f64 {
        match *self {
            ParamId::Link { joint, kind } => {
                let l = &data.links[joint - 1];
                match kind {
                    LinkParam::Alpha => l.alpha,
                    LinkParam::A => l.a,
                    LinkParam::Beta => l.beta,
                    LinkParam::ThetaOffset => l.theta_offset,
                    LinkParam::D => l.d,
                    LinkParam::Compliance => l.compliance,
                }
            }
            ParamId::Base(b) => {
                let f = &data.world_from_base;
                match b {
                    BaseParam::X => f.x,
                    BaseParam::Y => f.y,
                    BaseParam::Z => f.z,
                    BaseParam::Alpha => f.alpha,
                    BaseParam::Beta => f.beta,
                    BaseParam::Gamma => f.gamma,
                }
            }
            ParamId::Tool(k) => data.flange_tcp_mm[k],
        }
    }

    /// Sets the value in `data`, internal units.
    pub fn set(&self, data: &mut RobotData, v: f64) {
        match *self {
            ParamId::Link { joint, kind } => {
                let l = &mut data.links[joint - 1];
                match kind {
                    LinkParam::Alpha => l.alpha = v,
                    LinkParam::A => l.a = v,
                    LinkParam::Beta => l.beta = v,
                    LinkParam::ThetaOffset => l.theta_offset = v,
                    LinkParam::D => l.d = v,
                    LinkParam::Compliance => l.compliance = v,
                }
            }
            ParamId::Base(b) => {
                let f = &mut data.world_from_base;
                match b {
                    BaseParam::X => f.x = v,
                    BaseParam::Y => f.y = v,
                    BaseParam::Z => f.z = v,
                    BaseParam::Alpha => f.alpha = v,
                    BaseParam::Beta => f.beta = v,
                    BaseParam::Gamma => f.gamma = v,
                }
            }
            ParamId::Tool(k) => data.flange_tcp_mm[k] = v,
        }
    }

    /// Every parameter of the model, joints first (alpha, a, beta, theta_offs, d, c), then base, then tool.
    pub fn all() -> Vec<ParamId> {
        let kinds = [LinkParam::Alpha, LinkParam::A, LinkParam::Beta, LinkParam::ThetaOffset, LinkParam::D, LinkParam::Compliance];
        let mut v: Vec<ParamId> = (1..=JOINTS).flat_map(|j| kinds.map(|k| ParamId::link(j, k))).collect();
        v.extend(BASE_NAMES.iter().map(|(_, b)| ParamId::Base(*b)));
        v.extend((0..3).map(ParamId::Tool));
        v
    }
}

impl fmt::Display for ParamId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

/// Why a parameter set cannot be built or applied.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ParamError {
    /// A name that is not a parameter of the model.
    #[error("unknown parameter `{0}` (expected names such as alpha1, a2, beta2, d3, theta_offs4, c5, x0W, gamma0W, xT6)")]
    Unknown(String),
    /// A name given twice.
    #[error("parameter `{0}` is listed twice")]
    Duplicate(String),
    /// A vector of the wrong length.
    #[error("expected {expected} values, got {got}")]
    Length {
        /// Parameters in the set.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// The values make an invalid model.
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// An ordered set of free parameters: what an identification estimates.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParamSet {
    ids: Vec<ParamId>,
}

impl ParamSet {
    /// A set from explicit ids; rejects duplicates.
    pub fn new(ids: Vec<ParamId>) -> Result<Self, ParamError> {
        for (i, id) in ids.iter().enumerate() {
            if ids[..i].contains(id) {
                return Err(ParamError::Duplicate(id.name()));
            }
        }
        Ok(Self { ids })
    }

    /// A set from names in the paper's notation.
    pub fn from_names<S: AsRef<str>>(names: &[S]) -> Result<Self, ParamError> {
        let ids = names
            .iter()
            .map(|n| ParamId::parse(n.as_ref()).ok_or_else(|| ParamError::Unknown(n.as_ref().to_string())))
            .collect::<Result<Vec<_>, _>>()?;
        Self::new(ids)
    }

    /// The 31 parameters of the TriCal paper, in the order of its Table 7: alpha1..5, a1..5, d3..6,
    /// theta_offs2..6, c2..6, beta2, then the base x, y, z, alpha, beta, gamma.
    pub fn trical_31() -> Self {
        let mut names: Vec<String> = Vec::with_capacity(31);
        names.extend((1..=5).map(|i| format!("alpha{i}")));
        names.extend((1..=5).map(|i| format!("a{i}")));
        names.extend((3..=6).map(|i| format!("d{i}")));
        names.extend((2..=6).map(|i| format!("theta_offs{i}")));
        names.extend((2..=6).map(|i| format!("c{i}")));
        names.push("beta2".into());
        names.extend(BASE_NAMES.iter().map(|(n, _)| n.to_string()));
        Self::from_names(&names).expect("the paper's names are valid")
    }

    /// This set with `id` freed (appended) if it is not already free.
    pub fn freed(mut self, id: ParamId) -> Self {
        if !self.ids.contains(&id) {
            self.ids.push(id);
        }
        self
    }

    /// This set with `id` fixed (removed).
    pub fn fixed(mut self, id: ParamId) -> Self {
        self.ids.retain(|x| *x != id);
        self
    }

    /// The parameters, in order.
    pub fn ids(&self) -> &[ParamId] {
        &self.ids
    }

    /// Number of free parameters.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether no parameter is free.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Names, in order.
    pub fn names(&self) -> Vec<String> {
        self.ids.iter().map(ParamId::name).collect()
    }

    /// Position of `id` in the set.
    pub fn position(&self, id: ParamId) -> Option<usize> {
        self.ids.iter().position(|x| *x == id)
    }

    /// The model's values of these parameters, internal units.
    pub fn pack(&self, model: &RobotModel) -> DVector<f64> {
        DVector::from_iterator(self.ids.len(), self.ids.iter().map(|id| id.get(model.data())))
    }

    /// A copy of `model` with these parameters set to `values` (internal units).
    pub fn unpack(&self, model: &RobotModel, values: &[f64]) -> Result<RobotModel, ParamError> {
        if values.len() != self.ids.len() {
            return Err(ParamError::Length { expected: self.ids.len(), got: values.len() });
        }
        Ok(model.edited(|d| {
            for (id, v) in self.ids.iter().zip(values) {
                id.set(d, *v);
            }
        })?)
    }
}

/// The paper's name of a parameter given by any of its names, for tables (a name that is no
/// parameter's is returned as it is).
pub fn display_name(name: &str) -> String {
    ParamId::parse(name).map(|id| id.name()).unwrap_or_else(|| name.to_string())
}
