//! A real PostgreSQL + PostGIS server for the tests: started from the distribution's binaries in a
//! temporary directory on a free loopback port, shared by the tests that run at the same time,
//! stopped when the last of them drops it (on a panic too: unwinding drops it).
//!
//! PostgreSQL refuses to run as root, so as root the server runs as the `postgres` user (which
//! the distribution's package creates) in a directory handed to it. Missing binaries or a missing
//! PostGIS make the tests fail with the command that installs them: they are never skipped.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, Weak};

const SETUP: &str =
    "run `bash scripts/setup-postgres.sh` (as root) to install PostgreSQL and PostGIS";

/// A running server.
pub struct PgServer {
    dir: tempfile::TempDir,
    bin: PathBuf,
    port: u16,
    as_postgres: bool,
    databases: AtomicU32,
    create_lock: Mutex<()>,
}

/// The server the running tests share, started when none is.
pub fn shared() -> Arc<PgServer> {
    static SHARED: Mutex<Weak<PgServer>> = Mutex::new(Weak::new());
    let mut slot = SHARED.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(s) = slot.upgrade() {
        return s;
    }
    let s = Arc::new(PgServer::start());
    *slot = Arc::downgrade(&s);
    s
}

/// A server of its own, for a test that stops and restarts it (the others share [`shared`]).
pub fn dedicated() -> PgServer {
    PgServer::start()
}

impl PgServer {
    fn start() -> PgServer {
        let bin = find_bin();
        let root = run_output(Command::new("id").arg("-u")).trim() == "0";
        let dir = tempfile::Builder::new()
            .prefix("catalog-pg-")
            .tempdir()
            .expect("a temp dir");
        if root {
            let uid: u32 = run_output(Command::new("id").args(["-u", "postgres"]))
                .trim()
                .parse()
                .expect("uid");
            let gid: u32 = run_output(Command::new("id").args(["-g", "postgres"]))
                .trim()
                .parse()
                .expect("gid");
            std::os::unix::fs::chown(dir.path(), Some(uid), Some(gid)).expect("chown the temp dir");
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let server = PgServer {
            dir,
            bin,
            port,
            as_postgres: root,
            databases: AtomicU32::new(0),
            create_lock: Mutex::new(()),
        };
        let data = server.data();
        server.run(
            "initdb",
            &[
                "-D",
                &data,
                "-A",
                "trust",
                "-U",
                "postgres",
                "-E",
                "UTF8",
                "--no-sync",
            ],
        );
        server.start_server();
        let mut admin = server.connect("postgres");
        admin
            .batch_execute("CREATE DATABASE template_postgis")
            .expect("create the template database");
        let mut template = server.connect("template_postgis");
        template
            .batch_execute("CREATE EXTENSION postgis")
            .unwrap_or_else(|e| {
                panic!("CREATE EXTENSION postgis failed ({e}): PostGIS is not installed? {SETUP}")
            });
        server
    }

    /// Stops the server at once, as a crash would: `pg_ctl stop -m immediate` (every server
    /// process quits without a checkpoint; connections drop).
    pub fn stop_immediately(&self) {
        let data = self.data();
        self.run("pg_ctl", &["-D", &data, "-m", "immediate", "-w", "stop"]);
    }

    /// Freezes every process of the server (SIGSTOP), as a paused VM would: connections stay
    /// open and the kernel still acknowledges what is sent, but nothing answers.
    pub fn freeze(&self) {
        self.signal("STOP");
    }

    /// Lets a frozen server run on (SIGCONT).
    pub fn thaw(&self) {
        self.signal("CONT");
    }

    /// Sends `signal` to the postmaster and every process it started.
    fn signal(&self, signal: &str) {
        let pid_file = self.dir.path().join("data/postmaster.pid");
        let Some(pid) = std::fs::read_to_string(&pid_file)
            .ok()
            .and_then(|s| s.lines().next().map(str::to_owned))
        else {
            return; // not running
        };
        for (tool, args) in [
            ("pkill", ["-P", pid.as_str()]),
            ("kill", ["--", pid.as_str()]),
        ] {
            Command::new(tool)
                .arg(format!("-{signal}"))
                .args(args)
                .status()
                .unwrap_or_else(|e| panic!("{tool} -{signal}: {e}"));
        }
    }

    /// Starts the server again (after [`PgServer::stop_immediately`]) on the same port; it
    /// recovers from its write-ahead log first.
    pub fn start_again(&self) {
        self.start_server();
    }

    fn start_server(&self) {
        let data = self.data();
        let sock = self.dir.path().display().to_string();
        let opts = format!(
            "-p {} -k {sock} -c listen_addresses=127.0.0.1 -c fsync=off -c synchronous_commit=off \
             -c full_page_writes=off -c max_connections=200",
            self.port
        );
        let log = format!("{sock}/server.log");
        self.run(
            "pg_ctl",
            &[
                "-D", &data, "-o", &opts, "-l", &log, "-w", "-t", "120", "start",
            ],
        );
    }

    /// A fresh, empty database with PostGIS; its connection string.
    pub fn create_database(&self) -> String {
        let n = self.databases.fetch_add(1, Ordering::Relaxed);
        let name = format!("catalog_test_{n}");
        // Copies of one template must not run at once.
        let _one = self.create_lock.lock().unwrap_or_else(|e| e.into_inner());
        self.connect("postgres")
            .batch_execute(&format!("CREATE DATABASE {name} TEMPLATE template_postgis"))
            .expect("create a test database");
        self.url(&name)
    }

    /// The connection string for `database`.
    pub fn url(&self, database: &str) -> String {
        format!(
            "host=127.0.0.1 port={} user=postgres dbname={database} connect_timeout=10",
            self.port
        )
    }

    fn connect(&self, database: &str) -> postgres::Client {
        postgres::Client::connect(&self.url(database), postgres::NoTls)
            .unwrap_or_else(|e| panic!("connect to the test server: {e}"))
    }

    fn data(&self) -> String {
        self.dir.path().join("data").display().to_string()
    }

    fn run(&self, tool: &str, args: &[&str]) {
        let exe = self.bin.join(tool);
        let mut cmd = if self.as_postgres {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&exe);
            c
        } else {
            Command::new(&exe)
        };
        cmd.args(args).current_dir(self.dir.path());
        let out = cmd
            .output()
            .unwrap_or_else(|e| panic!("run {}: {e}. {SETUP}", exe.display()));
        if !out.status.success() {
            let log =
                std::fs::read_to_string(self.dir.path().join("server.log")).unwrap_or_default();
            panic!(
                "{tool} failed: {}\n{}\n{}\n{log}",
                out.status,
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }
}

impl Drop for PgServer {
    fn drop(&mut self) {
        // A frozen server would never stop.
        self.thaw();
        let exe = self.bin.join("pg_ctl");
        let data = self.data();
        let args = ["-D", data.as_str(), "-m", "immediate", "-w", "stop"];
        let mut cmd = if self.as_postgres {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&exe);
            c
        } else {
            Command::new(&exe)
        };
        // Best effort: a server that already stopped is fine.
        let _ = cmd.args(args).current_dir(self.dir.path()).output();
    }
}

/// The newest `/usr/lib/postgresql/*/bin` that has `initdb` and `pg_ctl`.
fn find_bin() -> PathBuf {
    let root = Path::new("/usr/lib/postgresql");
    let mut found: Vec<(u32, PathBuf)> = std::fs::read_dir(root)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let version: u32 = e.file_name().to_str()?.parse().ok()?;
            let bin = e.path().join("bin");
            (bin.join("initdb").exists() && bin.join("pg_ctl").exists()).then_some((version, bin))
        })
        .collect();
    found.sort();
    let Some((version, bin)) = found.pop() else {
        panic!("no PostgreSQL server binaries under /usr/lib/postgresql/*/bin: {SETUP}");
    };
    let control = format!("/usr/share/postgresql/{version}/extension/postgis.control");
    assert!(
        Path::new(&control).exists(),
        "PostGIS is not installed for PostgreSQL {version} ({control} is missing): {SETUP}"
    );
    bin
}

fn run_output(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}
