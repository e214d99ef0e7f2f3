//! The method table: every hole-filling method with the one name the policy, the log
//! and the command line spell it by. The dispatch (`fill::dispatch`) runs a method by
//! its [`Method`]; the policy reads and writes it by the name here, so a method's name
//! is written in this table and nowhere else.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A hole-filling method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// Centroid fan (paper 002 §5.1).
    Fan,
    /// Minimum-area triangulation, refinement, fairing (paper 002 §5.2).
    MinAreaFair,
    /// Improved advancing front (paper 002 §5.3).
    AdvancingFront,
    /// Plain advancing front, LS-SVM prediction of the Laplacian, Poisson solve (paper 003).
    LssvmPoisson,
    /// Improved wavefront with curvature restoration (paper 004, Huang et al. 2022).
    Wavefront,
    /// Prediction by differential evolution + constrained Delaunay (paper 000).
    Hpde,
    /// Triangles over the loop's own vertices, checks relaxed to allow slivers: the
    /// last method of every default list (not from a paper; `fill::close`).
    Close,
}

/// Every method and its policy name, in the order the policy documents them.
pub const METHODS: &[(Method, &str)] = &[
    (Method::Fan, "fan"),
    (Method::MinAreaFair, "min_area_fair"),
    (Method::AdvancingFront, "advancing_front"),
    (Method::LssvmPoisson, "lssvm_poisson"),
    (Method::Wavefront, "wavefront"),
    (Method::Hpde, "hpde"),
    (Method::Close, "close"),
];

impl Method {
    /// Every method, in table order.
    pub const ALL: &'static [Method] = &[
        METHODS[0].0,
        METHODS[1].0,
        METHODS[2].0,
        METHODS[3].0,
        METHODS[4].0,
        METHODS[5].0,
        METHODS[6].0,
    ];
    /// The policy spelling.
    pub fn name(self) -> &'static str {
        METHODS
            .iter()
            .find(|(m, _)| *m == self)
            .map_or("", |(_, n)| n)
    }
    /// The method spelled `name`, if any.
    pub fn from_name(name: &str) -> Option<Method> {
        METHODS.iter().find(|(_, n)| *n == name).map(|(m, _)| *m)
    }
}

impl Serialize for Method {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Method {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Method, D::Error> {
        let name = String::deserialize(d)?;
        Method::from_name(&name)
            .ok_or_else(|| serde::de::Error::custom(format!("unknown method `{name}`")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_lists_every_method_once() {
        assert_eq!(Method::ALL.len(), METHODS.len());
        for (i, (m, n)) in METHODS.iter().enumerate() {
            assert_eq!(Method::ALL[i], *m);
            assert_eq!(m.name(), *n);
            assert_eq!(Method::from_name(n), Some(*m));
            assert_eq!(serde_json::to_string(m).unwrap(), format!("\"{n}\""));
        }
        assert_eq!(Method::from_name("fans"), None);
    }
}
