//! Choosing a store from configuration: a file path or a PostgreSQL URL.

use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::postgis::PostgisStore;
use crate::sqlite::SqliteStore;
use crate::store::Store;

/// Where the catalog lives: the server's `[catalog] path` (SQLite) or `[catalog] url`
/// (PostgreSQL + PostGIS).
#[derive(Clone, PartialEq, Eq)]
pub enum Location {
    /// One SQLite file (created when missing).
    Sqlite(PathBuf),
    /// A PostgreSQL database with PostGIS: `postgres://user:password@host:port/database` or the
    /// key=value form.
    Postgres(String),
}

impl Location {
    /// `postgres://…` and `postgresql://…` are databases; anything else is a file path. Empty is
    /// refused naming `field`.
    pub fn parse(value: &str, field: &str) -> Result<Self> {
        let v = value.trim();
        if v.is_empty() {
            return Err(Error::invalid(
                field,
                "empty: a SQLite file path or a postgres:// URL",
            ));
        }
        if v.starts_with("postgres://") || v.starts_with("postgresql://") {
            Ok(Location::Postgres(v.to_string()))
        } else {
            Ok(Location::Sqlite(PathBuf::from(v)))
        }
    }

    /// Opens the store (migrations included). Blocks; see [`Store`].
    pub fn open(&self) -> Result<Box<dyn Store>> {
        Ok(match self {
            Location::Sqlite(path) => Box::new(SqliteStore::open(path)?),
            Location::Postgres(url) => Box::new(PostgisStore::connect(url)?),
        })
    }
}

impl std::fmt::Debug for Location {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Location::Sqlite(p) => f.debug_tuple("Sqlite").field(p).finish(),
            // The URL may hold a password: show only the scheme.
            Location::Postgres(_) => f.write_str("Postgres(postgres://…)"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_paths_and_urls_and_hides_passwords() {
        let pg = Location::parse("postgres://fleet:secret@db:5432/catalog", "catalog.url").unwrap();
        assert!(matches!(pg, Location::Postgres(_)));
        assert!(!format!("{pg:?}").contains("secret"));
        assert_eq!(
            Location::parse("/var/lib/landing/catalog.sqlite", "catalog.path").unwrap(),
            Location::Sqlite("/var/lib/landing/catalog.sqlite".into())
        );
        assert_eq!(
            Location::parse(" ", "catalog.path").unwrap_err().field(),
            Some("catalog.path")
        );
        let dir = std::env::temp_dir().join(format!("catalog-open-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let store = Location::Sqlite(dir.join("c.sqlite")).open().unwrap();
        assert_eq!(store.backend(), "sqlite");
        drop(store);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
