fn main() {
    let p = std::env::args().nth(1).unwrap();
    let b = std::fs::read(&p).unwrap();
    let h = navsync_receivers::stream::gpsd_log_header_len(&b);
    let (ev, st) = navsync_receivers::stream::read_all(&b[h..], h as u64);
    for e in &ev {
        match &e.kind {
            navsync_receivers::EventKind::Unknown(_) => {}
            k => println!("{} {} {:?}", e.offset, e.len, k),
        }
    }
    println!("{st:?}");
}
