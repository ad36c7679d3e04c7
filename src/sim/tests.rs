//! Checklist tests of the simulated drive, sans-I/O (in progress).
