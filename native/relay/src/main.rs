//! A delaying TCP relay for RingTracer's network benchmark.
//!
//! ```text
//! ringtracer-relay LISTEN=TARGET [LISTEN=TARGET ...]
//! ```
//!
//! Each argument is a route: a listener at `LISTEN` (an `ip:port`) whose
//! every connection is forwarded to `TARGET`. Every byte is held for the
//! one-way delay before it goes on, in both directions. The relay prints
//! `ready` once every listener is bound, then reads commands on its standard
//! input, one per line: `delay MICROSECONDS` sets the delay for every byte
//! read from then on (answered with `ok`). The end of its input stops it.
//!
//! Per direction of a connection, one thread reads and stamps each chunk
//! with `arrival + delay`, and another writes each chunk out at its time,
//! in order: a chunk waits for its own deadline, not behind the chunks
//! before it, so the delay does not cut the throughput. At most
//! `QUEUE` chunks wait per direction; beyond that the reader stops
//! reading and TCP pushes back on the sender. The relay ends TCP on both
//! sides, so it delays data, not acknowledgements.

use std::io::{self, BufRead, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

/// Bytes read at most at once.
const CHUNK: usize = 65_536;
/// Chunks waiting per direction (at most 4 MiB).
const QUEUE: usize = 64;

type Chunk = (Instant, Vec<u8>);

fn main() {
    let routes: Vec<(SocketAddr, SocketAddr)> = match std::env::args().skip(1).map(route).collect()
    {
        Ok(routes) => routes,
        Err(message) => {
            eprintln!("ringtracer-relay: {message}");
            eprintln!("usage: ringtracer-relay LISTEN_IP:PORT=TARGET_IP:PORT ...");
            std::process::exit(2);
        }
    };

    let delay = Arc::new(AtomicU64::new(0));
    let mut listeners = Vec::new();
    for (listen, target) in routes {
        match TcpListener::bind(listen) {
            Ok(listener) => listeners.push((listener, target)),
            Err(e) => {
                eprintln!("ringtracer-relay: cannot listen on {listen}: {e}");
                std::process::exit(1);
            }
        }
    }
    for (listener, target) in listeners {
        let delay = Arc::clone(&delay);
        thread::spawn(move || accept(listener, target, delay));
    }

    let mut out = io::stdout();
    let _ = writeln!(out, "ready");
    let _ = out.flush();
    for line in io::stdin().lock().lines() {
        let Ok(line) = line else { break };
        let answer = match line.trim().strip_prefix("delay ").map(str::parse::<u64>) {
            Some(Ok(us)) => {
                delay.store(us, Ordering::Relaxed);
                "ok".to_string()
            }
            _ => format!("error: unknown command {line:?}"),
        };
        let _ = writeln!(out, "{answer}");
        let _ = out.flush();
    }
    std::process::exit(0);
}

fn route(arg: String) -> Result<(SocketAddr, SocketAddr), String> {
    let (listen, target) = arg
        .split_once('=')
        .ok_or_else(|| format!("a route is LISTEN=TARGET, got {arg:?}"))?;
    let parse = |s: &str| {
        s.parse::<SocketAddr>()
            .map_err(|_| format!("not an ip:port: {s:?}"))
    };
    Ok((parse(listen)?, parse(target)?))
}

fn accept(listener: TcpListener, target: SocketAddr, delay: Arc<AtomicU64>) {
    for inbound in listener.incoming() {
        let Ok(inbound) = inbound else { continue };
        let Ok(outbound) = TcpStream::connect_timeout(&target, Duration::from_secs(10)) else {
            continue;
        };
        let _ = inbound.set_nodelay(true);
        let _ = outbound.set_nodelay(true);
        for (from, to) in [
            (inbound.try_clone(), outbound.try_clone()),
            (outbound.try_clone(), inbound.try_clone()),
        ] {
            if let (Ok(from), Ok(to)) = (from, to) {
                let delay = Arc::clone(&delay);
                thread::spawn(move || pipe(from, to, &delay));
            }
        }
    }
}

/// One direction of a connection: read here, write in a thread of its own.
fn pipe(from: TcpStream, to: TcpStream, delay: &AtomicU64) {
    let (tx, rx) = sync_channel::<Chunk>(QUEUE);
    let writer = thread::spawn(move || write_out(rx, to));
    read_in(from, tx, delay);
    let _ = writer.join();
}

fn read_in(mut from: TcpStream, tx: SyncSender<Chunk>, delay: &AtomicU64) {
    let mut buf = vec![0u8; CHUNK];
    loop {
        match from.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                let due = Instant::now() + Duration::from_micros(delay.load(Ordering::Relaxed));
                if tx.send((due, buf[..n].to_vec())).is_err() {
                    break;
                }
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(_) => break,
        }
    }
}

fn write_out(rx: Receiver<Chunk>, mut to: TcpStream) {
    for (due, data) in rx {
        let now = Instant::now();
        if due > now {
            thread::sleep(due - now);
        }
        if to.write_all(&data).is_err() {
            break;
        }
    }
    // What was read before the sender closed has all gone out: close this way too.
    let _ = to.shutdown(Shutdown::Write);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn routes_parse() {
        let (l, t) = route("10.77.0.1:9101=10.77.1.2:9101".to_string()).unwrap();
        assert_eq!(l.to_string(), "10.77.0.1:9101");
        assert_eq!(t.to_string(), "10.77.1.2:9101");
        assert!(route("10.77.0.1:9101".to_string()).is_err());
        assert!(route("a=b".to_string()).is_err());
    }

    #[test]
    fn bytes_arrive_in_order_after_the_delay() {
        let target = TcpListener::bind("127.0.0.1:0").unwrap();
        let target_addr = target.local_addr().unwrap();
        let relay = TcpListener::bind("127.0.0.1:0").unwrap();
        let relay_addr = relay.local_addr().unwrap();
        let delay = Arc::new(AtomicU64::new(20_000));
        thread::spawn(move || accept(relay, target_addr, delay));

        let mut client = TcpStream::connect(relay_addr).unwrap();
        let (mut server, _) = target.accept().unwrap();
        let data: Vec<u8> = (0..200_000u32).map(|i| (i % 251) as u8).collect();
        let t0 = Instant::now();
        client.write_all(&data).unwrap();
        client.shutdown(Shutdown::Write).unwrap();
        let mut got = Vec::new();
        server.read_to_end(&mut got).unwrap();
        assert!(t0.elapsed() >= Duration::from_millis(20));
        assert_eq!(got, data);
    }
}
