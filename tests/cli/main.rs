//! Files in, files out, no running daemon: the offline subcommands ([`cli`]), `visobjd
//! import` ([`import`]), the shipped demo stage ([`demo`]) and the fuzz targets' corpus
//! ([`fuzz_corpus`]).

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod demo;
mod fuzz_corpus;
mod import;
