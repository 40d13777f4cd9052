fn main() {
    eprintln!("wlnavd: not yet implemented");
    std::process::exit(2);
}
