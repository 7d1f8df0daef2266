//! A Mosquitto of a test (its own port, config file and directory, killed on drop) and a
//! subscriber recording what it receives: for tests/mqtt.rs and the daemon outage of tests/rtsp.rs.
//! Mosquitto comes from Debian's package (`make setup`); without it these tests fail, naming it.
#![allow(dead_code)]

use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A program of the mosquitto package: on PATH, else where Debian puts it (/usr/sbin is not on a
/// non-root PATH).
pub fn mosquitto_program(name: &str) -> PathBuf {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .chain(["/usr/sbin", "/usr/bin", "/usr/local/sbin", "/usr/local/bin"].map(|d| Path::new(d).join(name)))
        .find(|p| p.is_file())
        .unwrap_or_else(|| {
            panic!("`{name}` not found on PATH or in /usr/sbin: run `make setup` (it installs Debian's mosquitto)")
        })
}

/// A free loopback port (bound, then released).
pub fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind an ephemeral port");
    l.local_addr().expect("local addr").port()
}

/// A Mosquitto of this test: its own port, config file and directory; killed on drop.
pub struct Broker {
    child: Option<Child>,
    conf: PathBuf,
    pub port: u16,
    pub dir: tempfile::TempDir,
}

impl Broker {
    /// Starts a broker on a free loopback port; `extra` is appended to its config file (it may
    /// refer to `{dir}`, the broker's directory).
    pub fn start(extra: &str) -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        let port = free_port();
        let conf = dir.path().join("mosquitto.conf");
        // `user root` only matters when the tests run as root (CI): mosquitto then stays root
        // instead of switching to the `mosquitto` user, which could not read the temp dir.
        let text = format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\nuser root\n{}\n",
            extra.replace("{dir}", &dir.path().to_string_lossy())
        );
        std::fs::write(&conf, text).expect("write mosquitto.conf");
        let mut b = Self { child: None, conf, port, dir };
        b.restart();
        b
    }

    /// Starts the broker again on the same port with the same config.
    pub fn restart(&mut self) {
        let log = std::fs::File::create(self.dir.path().join("mosquitto.log")).expect("log file");
        let child = Command::new(mosquitto_program("mosquitto"))
            .arg("-c")
            .arg(&self.conf)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("start mosquitto");
        self.child = Some(child);
        let end = Instant::now() + Duration::from_secs(10);
        while std::net::TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            assert!(Instant::now() < end, "mosquitto did not listen on {} within 10 s: {}", self.port, self.log());
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Stops the broker with SIGTERM (it saves its persistence file) and waits for it.
    pub fn stop(&mut self) {
        if let Some(mut c) = self.child.take() {
            // SAFETY: kill(2) on the pid of our own child.
            unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
            let _ = c.wait();
        }
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("mosquitto.log")).unwrap_or_default()
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// One received message.
#[derive(Debug, Clone)]
pub struct Msg {
    pub topic: String,
    pub payload: String,
    pub retain: bool,
}

/// A subscriber on `filter`, reconnecting every 100 ms while the broker is away.
pub struct Sub {
    msgs: Arc<Mutex<Vec<Msg>>>,
    task: tokio::task::JoinHandle<()>,
}

impl Sub {
    pub fn start(port: u16, id: &str, filter: &str, clean: bool) -> Self {
        let mut o = MqttOptions::new(id, "127.0.0.1", port);
        o.set_clean_session(clean);
        o.set_keep_alive(Duration::from_secs(5));
        o.set_max_packet_size(1 << 20, 1 << 20);
        let (client, mut el) = AsyncClient::new(o, 16);
        let msgs = Arc::new(Mutex::new(Vec::new()));
        let (m, filter) = (msgs.clone(), filter.to_string());
        let task = tokio::spawn(async move {
            loop {
                match el.poll().await {
                    Ok(Event::Incoming(Packet::ConnAck(_))) => {
                        let _ = client.try_subscribe(filter.clone(), QoS::AtLeastOnce);
                    }
                    Ok(Event::Incoming(Packet::Publish(p))) => m.lock().expect("lock").push(Msg {
                        topic: p.topic.clone(),
                        payload: String::from_utf8_lossy(&p.payload).into_owned(),
                        retain: p.retain,
                    }),
                    Ok(_) => {}
                    Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
                }
            }
        });
        Self { msgs, task }
    }

    pub fn all(&self) -> Vec<Msg> {
        self.msgs.lock().expect("lock").clone()
    }

    pub fn on(&self, topic: &str) -> Vec<Msg> {
        self.all().into_iter().filter(|m| m.topic == topic).collect()
    }
}

impl Drop for Sub {
    fn drop(&mut self) {
        self.task.abort();
    }
}
