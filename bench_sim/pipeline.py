"""One pass: frames -> sensor -> DTDI -> stage images and their truth."""
