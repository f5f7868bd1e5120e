//! The four stations of a floor: what every model predicts, every vote and decision
//! names, and every station object marks.
//!
//! On the wire (and in JSON) a station is its index, one byte, exactly what the
//! protocol carried before this type existed; decoding a byte that names no station
//! fails with an error saying so. "No decision" is `Option<Station>::None`, never a
//! reserved value.

use serde::{Deserialize, Serialize};

/// How many stations there are: the models' class count.
pub const NUM_CLASSES: usize = 4;

/// A station (paper Table I), by the kind of work done there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(into = "u8", try_from = "u8")]
pub enum Station {
    Storage,
    Workstation,
    Assembly,
    Manufacturing,
}

impl Station {
    /// Every station in index order (the models' class order).
    pub const ALL: [Station; NUM_CLASSES] =
        [Station::Storage, Station::Workstation, Station::Assembly, Station::Manufacturing];

    /// Its index: the models' class and the byte on the wire.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The station of a class index, if it names one.
    pub fn from_index(index: usize) -> Option<Station> {
        Station::ALL.get(index).copied()
    }

    /// Its name, as layouts, logs and the demo show it.
    pub const fn name(self) -> &'static str {
        match self {
            Station::Storage => "storage",
            Station::Workstation => "workstation",
            Station::Assembly => "assembly",
            Station::Manufacturing => "manufacturing",
        }
    }
}

/// In JSON, as on the wire, a station is its index.
impl schemars::JsonSchema for Station {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "Station".into()
    }
    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "type": "integer",
            "minimum": 0,
            "maximum": NUM_CLASSES - 1,
            "description": "0 storage area, 1 workstation, 2 assembly station, 3 manufacturing station",
        })
    }
}

impl std::fmt::Display for Station {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.name())
    }
}

impl From<Station> for u8 {
    fn from(s: Station) -> u8 {
        s as u8
    }
}

/// A byte that names no station.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("station {0} out of range 0..{NUM_CLASSES}")]
pub struct UnknownStation(pub u8);

impl TryFrom<u8> for Station {
    type Error = UnknownStation;
    fn try_from(b: u8) -> Result<Station, UnknownStation> {
        Station::from_index(b.into()).ok_or(UnknownStation(b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_byte_and_name_round_trip() {
        for (i, s) in Station::ALL.into_iter().enumerate() {
            assert_eq!(s.index(), i);
            assert_eq!(Station::try_from(u8::from(s)), Ok(s));
            assert_eq!(Station::from_index(i), Some(s));
        }
        assert_eq!(Station::try_from(4), Err(UnknownStation(4)));
        assert_eq!(Station::from_index(4), None);
        assert_eq!(Station::Assembly.to_string(), "assembly");
    }
}
