//! Scraping a Prometheus endpoint in the tests (`holefill watch --metrics`,
//! `holefill worker --metrics`): a bare HTTP/1.1 GET and the samples of the text.
#![allow(dead_code)]

use std::collections::HashMap;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, SystemTime};

/// A free port on the loopback interface.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// `GET path`: status line and body.
pub fn get(port: u16, path: &str) -> (String, String) {
    let mut s = TcpStream::connect(("127.0.0.1", port)).expect("connect to the metrics port");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(s, "GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    (
        head.lines().next().unwrap_or("").to_string(),
        body.to_string(),
    )
}

pub fn scrape(port: u16) -> String {
    let (status, body) = get(port, "/metrics");
    assert_eq!(status, "HTTP/1.1 200 OK");
    body
}

/// The value of the sample `name` (with its labels exactly as written), if present.
pub fn sample(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(name).and_then(|r| r.strip_prefix(' ')))
        .map(|v| v.trim().parse().unwrap_or_else(|_| panic!("{name}: {v}")))
}

pub fn must(text: &str, name: &str) -> f64 {
    sample(text, name).unwrap_or_else(|| panic!("no sample {name} in\n{text}"))
}

/// Every sample of a metric family: labels text -> value.
pub fn family(text: &str, name: &str) -> HashMap<String, f64> {
    text.lines()
        .filter_map(|l| l.strip_prefix(name)?.strip_prefix('{'))
        .filter_map(|r| {
            let (labels, v) = r.split_once("} ")?;
            Some((labels.to_string(), v.trim().parse().ok()?))
        })
        .collect()
}

pub fn now_secs() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// What `holefill_holes_total` must hold for these repair logs: per label set
/// (`status="..",class="..",method=".."`), the number of holes.
pub fn holes_by_label<'a>(
    logs: impl IntoIterator<Item = &'a serde_json::Value>,
) -> HashMap<String, f64> {
    let mut want: HashMap<String, f64> = HashMap::new();
    for log in logs {
        for h in log["holes"].as_array().into_iter().flatten() {
            let s = |k: &str| h[k].as_str().unwrap_or("none").to_string();
            let key = format!(
                "status=\"{}\",class=\"{}\",method=\"{}\"",
                s("status"),
                s("class"),
                s("method")
            );
            *want.entry(key).or_default() += 1.0;
        }
    }
    want
}
