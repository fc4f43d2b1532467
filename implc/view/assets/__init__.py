"""The viewer page's files (index.html, viewer.css, viewer.js), shipped as package data; no code."""
