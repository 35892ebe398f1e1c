//! The crate's one error type.

/// Everything the catalog can refuse or fail at.
///
/// The server maps [`Error::InvalidArgument`] to `INVALID_ARGUMENT` (its `field` is the request's
/// field path, e.g. `page_token`, `center.latitude_deg`, `observations[2].sites[0].safe_radius_m`)
/// and every storage variant to `UNAVAILABLE` naming the catalog.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A caller's value is out of range or malformed; `field` names it.
    #[error("invalid {field}: {reason}")]
    InvalidArgument {
        /// The field path, as the request spells it.
        field: String,
        /// What is wrong with it, with the bad value.
        reason: String,
    },
    /// The database refused or failed a call (connection lost, disk full, lock timeout...).
    #[error("catalog storage ({backend}) failed: {source}")]
    Storage {
        /// `sqlite` or `postgis`.
        backend: &'static str,
        /// The driver's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The database holds data this code cannot read: a schema newer than this build, a row
    /// that does not parse, or a failed integrity check.
    #[error("catalog data ({backend}) is not usable: {what}")]
    Corrupt {
        /// `sqlite` or `postgis`.
        backend: &'static str,
        /// What was found.
        what: String,
    },
}

impl Error {
    /// An [`Error::InvalidArgument`] for `field`.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::InvalidArgument {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// The field an [`Error::InvalidArgument`] names, else `None`.
    pub fn field(&self) -> Option<&str> {
        match self {
            Error::InvalidArgument { field, .. } => Some(field),
            Error::Storage { .. } | Error::Corrupt { .. } => None,
        }
    }
}

/// The crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
