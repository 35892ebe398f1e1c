//! The semantic classes of the paper: one table shared by the simulator, the segmentation model,
//! point classification and the API (`landing.v1.SemanticClass` has the same numbers).

/// A semantic class. The numbers are the packed class bytes of point clouds and the values of the
/// segmentation mask; 0 means unknown.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum SemanticClass {
    Unknown = 0,
    Sky = 1,
    Ground = 2,
    BuildingWall = 3,
    BuildingRooftop = 4,
    SmallRooftopEntrance = 5,
    Skylight = 6,
    AirVents = 7,
    AcUnit = 8,
    Seating = 9,
    AirDucts = 10,
    WaterTower = 11,
    Chimney = 12,
    Tarp = 13,
    Vegetation = 14,
}

impl SemanticClass {
    /// Every class, in numeric order, `Unknown` first.
    pub const ALL: [SemanticClass; 15] = [
        Self::Unknown,
        Self::Sky,
        Self::Ground,
        Self::BuildingWall,
        Self::BuildingRooftop,
        Self::SmallRooftopEntrance,
        Self::Skylight,
        Self::AirVents,
        Self::AcUnit,
        Self::Seating,
        Self::AirDucts,
        Self::WaterTower,
        Self::Chimney,
        Self::Tarp,
        Self::Vegetation,
    ];

    /// Number of classes including `Unknown` (the segmentation model's output channels).
    pub const COUNT: usize = Self::ALL.len();

    /// The class with this number, if any.
    pub fn from_u8(id: u8) -> Option<Self> {
        Self::ALL.get(usize::from(id)).copied()
    }

    /// The paper's name of the class, e.g. "building rooftop".
    pub fn name(self) -> &'static str {
        match self {
            Self::Unknown => "unknown",
            Self::Sky => "sky",
            Self::Ground => "ground",
            Self::BuildingWall => "building wall",
            Self::BuildingRooftop => "building rooftop",
            Self::SmallRooftopEntrance => "small rooftop entrance",
            Self::Skylight => "skylight",
            Self::AirVents => "air vents",
            Self::AcUnit => "ac-unit",
            Self::Seating => "seating",
            Self::AirDucts => "air ducts",
            Self::WaterTower => "water tower",
            Self::Chimney => "chimney",
            Self::Tarp => "tarp",
            Self::Vegetation => "vegetation",
        }
    }
}
