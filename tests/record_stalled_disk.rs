//! A recording whose disk stalls does not stall the sessions (issue 47): the recorder's file
//! work runs on a thread of its own, never on the async workers. Here the proxy and the
//! simulated reader behind it run on one async worker, as `sim` does, and the recording goes
//! to a sink whose writes block until the test lets them through: a client still gets every
//! answer while nothing has reached the sink. (When the recorder wrote on the async worker,
//! its first blocked write held the only worker, and the client got nothing.) Once the sink
//! is let through, the recording holds the session byte for byte.

mod common;

use std::io::{self, Write};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

use llrp::message::{GetReaderCapabilities, GetReaderConfig};
use llrp_gateway::net::client::Client;
use llrp_gateway::net::clock::Speed;
use llrp_gateway::net::proxy::{Proxy, ProxyConfig};
use llrp_gateway::record::{Direction, Entry, Header, RecordOptions, Recorder, Recording, Sink};
use tokio::sync::watch;

/// A disk that stalls: every write waits until [`Gate::open`]; what gets through is kept.
#[derive(Clone, Default)]
struct Gate {
    state: Arc<(Mutex<GateState>, Condvar)>,
}

#[derive(Default)]
struct GateState {
    open: bool,
    /// Writes waiting at the gate now.
    waiting: usize,
    written: Vec<u8>,
}

impl Gate {
    fn open(&self) {
        let (lock, wake) = &*self.state;
        lock.lock().expect("gate").open = true;
        wake.notify_all();
    }

    /// (writes waiting at the gate, bytes through it).
    fn seen(&self) -> (usize, usize) {
        let g = self.state.0.lock().expect("gate");
        (g.waiting, g.written.len())
    }

    fn written(&self) -> Vec<u8> {
        self.state.0.lock().expect("gate").written.clone()
    }
}

impl Write for Gate {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let (lock, wake) = &*self.state;
        let mut g = lock.lock().expect("gate");
        g.waiting += 1;
        while !g.open {
            g = wake.wait(g).expect("gate");
        }
        g.waiting -= 1;
        g.written.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Opens the gate when dropped: a test that fails lets the writer go, so that its runtime can
/// end (declared after the runtime, it is dropped before it).
struct OpenOnDrop(Gate);

impl Drop for OpenOnDrop {
    fn drop(&mut self) {
        self.0.open();
    }
}

impl Sink for Gate {
    type Part = Gate;

    fn open(&mut self, _part: u32) -> io::Result<Gate> {
        Ok(self.clone())
    }

    fn sync(&mut self, _file: &mut Gate) -> io::Result<()> {
        Ok(())
    }

    fn name(&self, part: u32) -> String {
        format!("gate part {part}")
    }
}

/// The proxy recording into `gate`, to a simulated reader, both served on `server`: the
/// proxy's address, its stop, its task (which stops the reader after it) and the recording.
type Served = (
    std::net::SocketAddr,
    watch::Sender<bool>,
    tokio::task::JoinHandle<io::Result<()>>,
    llrp_gateway::record::RecorderTask,
);

fn serve(server: &tokio::runtime::Runtime, gate: &Gate) -> Served {
    server.block_on(async {
        let sim = common::start(&common::s1(), Speed::Factor(1.0)).await;
        let upstream = sim.addrs[0].to_string();
        let header = Header::new(&upstream, 0);
        let (recorder, recording) =
            Recorder::start(gate.clone(), header, RecordOptions::default()).expect("recording");
        let config = ProxyConfig {
            name: llrp_gateway::reads::ReaderName::parse("stalled").expect("a valid reader name"),
            upstream,
            listen: "127.0.0.1:0".into(),
            record: None,
            region: None,
            connect_timeout: Duration::from_secs(5),
            tls: None,
            upstream_tls: None,
        };
        let p = Proxy::bind(config, Some(recorder), None)
            .await
            .expect("binds");
        let addr = p.local_addr().expect("bound");
        let (stop, rx) = watch::channel(false);
        let proxy = tokio::spawn(async move {
            let ran = p.run(rx).await;
            sim.shutdown().await;
            ran
        });
        (addr, stop, proxy, recording)
    })
}

/// A client's session through the proxy at `addr`, on a runtime of its own: the greeting, 15
/// requests each answered, CLOSE_CONNECTION; the answers counted.
fn session(addr: std::net::SocketAddr) -> usize {
    let client = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    client.block_on(async {
        let mut c = Client::connect_reader(addr, common::T)
            .await
            .expect("greeted through the proxy while the recording is stalled");
        let mut answers = 0;
        for _ in 0..5 {
            c.capabilities(common::T)
                .await
                .expect("capabilities while the recording is stalled");
            c.request(GetReaderConfig::default(), common::T)
                .await
                .expect("a config while the recording is stalled");
            c.request(GetReaderCapabilities::default(), common::T)
                .await
                .expect("an answer while the recording is stalled");
            answers += 3;
        }
        c.close_connection(common::T)
            .await
            .expect("closed while the recording is stalled");
        answers
    })
}

/// The frames of `r` that went `dir`.
fn frames(r: &Recording, dir: Direction) -> usize {
    let went = |e: &&Entry| matches!(e, Entry::Frame { dir: d, .. } if *d == dir);
    r.entries.iter().filter(went).count()
}

#[test]
fn a_stalled_recording_does_not_stall_the_session() {
    // One async worker, as `sim` runs: a blocking write on it would stop every socket.
    let server = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .expect("runtime");
    let gate = Gate::default();
    let _release = OpenOnDrop(gate.clone());
    let (addr, stop, proxy, recording) = serve(&server, &gate);

    // The writer is held at the gate (its first write, the header's) before the client starts.
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while gate.seen().0 == 0 {
        let waited = std::time::Instant::now() < deadline;
        assert!(waited, "the writer never wrote");
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(session(addr), 15);
    let (waiting, through) = gate.seen();
    assert_eq!(through, 0, "the session ran while nothing reached the disk");
    assert_eq!(waiting, 1, "the writer is held at its first write");

    // Let the disk go: the recording is then whole.
    gate.open();
    server.block_on(async {
        let _ = stop.send(true);
        proxy.await.expect("joined").expect("proxy ran");
        recording.await.expect("joined").expect("recording written");
    });
    let r = Recording::read(&gate.written()[..]).expect("a recording");
    // 15 requests and the CLOSE_CONNECTION; the greeting and every answer.
    assert_eq!(frames(&r, Direction::ToReader), 16, "{:?}", r.entries.len());
    let from_reader = frames(&r, Direction::FromReader);
    assert!(from_reader >= 17, "{from_reader} frames from the reader");
}
