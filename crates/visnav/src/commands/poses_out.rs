//! `--poses-out`: one JSON line ([`PoseLine`]) a frame as it happens, to standard output or
//! as UDP datagrams, for `visnav odometry` on a recording or a live input.

use std::io::Write as _;
use std::net::{ToSocketAddrs as _, UdpSocket};

use anyhow::{Context as _, bail};
use visnav_pipeline::{Arrival, FrameResult, PoseLine};

/// Where `--poses-out` sends the lines.
enum Sink {
    Stdout(std::io::Stdout),
    Udp(UdpSocket),
}

/// The `--poses-out` writer: one JSON line ([`PoseLine`]) a frame, flushed (standard output) or
/// sent as one datagram (UDP). A consumer that goes away is a warning, not the end of the run.
pub struct PosesOut {
    sink: Sink,
    target: String,
    failed: bool,
}

impl PosesOut {
    /// Opens `-` (standard output) or `udp://HOST:PORT`.
    ///
    /// # Errors
    /// Another target, or an address that does not resolve.
    pub fn open(target: &str) -> anyhow::Result<Self> {
        let sink = if target == "-" {
            Sink::Stdout(std::io::stdout())
        } else if let Some(addr) = target.strip_prefix("udp://") {
            let to = addr
                .to_socket_addrs()
                .with_context(|| format!("--poses-out {target}: not a HOST:PORT address"))?
                .next()
                .with_context(|| format!("--poses-out {target}: the address does not resolve"))?;
            let any = if to.is_ipv4() { "0.0.0.0:0" } else { "[::]:0" };
            let socket = UdpSocket::bind(any)
                .and_then(|s| s.connect(to).map(|()| s))
                .with_context(|| format!("--poses-out {target}: cannot open a UDP socket"))?;
            Sink::Udp(socket)
        } else {
            bail!(
                "--poses-out {target}: give - (standard output) or udp://HOST:PORT (one JSON line a frame)"
            );
        };
        Ok(Self {
            sink,
            target: target.to_owned(),
            failed: false,
        })
    }

    /// Whether the lines go to standard output (the human output then goes to stderr).
    #[must_use]
    pub fn is_stdout(target: Option<&str>) -> bool {
        target == Some("-")
    }

    /// Writes the line of a frame.
    pub fn send(&mut self, r: &FrameResult, arrival: &Arrival) {
        if self.failed {
            return;
        }
        let line = match PoseLine::new(r, arrival).to_json() {
            Ok(l) => l,
            Err(e) => {
                log::warn!("--poses-out: frame {}: {e}", r.position);
                return;
            }
        };
        let sent = match &mut self.sink {
            Sink::Stdout(out) => {
                let mut out = out.lock();
                writeln!(out, "{line}").and_then(|()| out.flush())
            }
            Sink::Udp(s) => s.send(line.as_bytes()).map(|_| ()),
        };
        if let Err(e) = sent {
            // UDP: nobody listens (yet): the next datagram may find a listener
            if matches!(self.sink, Sink::Udp(_))
                && e.kind() == std::io::ErrorKind::ConnectionRefused
            {
                return;
            }
            log::warn!(
                "--poses-out {}: {e}; no more pose lines are sent (the run goes on)",
                self.target
            );
            self.failed = true;
        }
    }
}
