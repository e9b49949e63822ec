"""Worker-thread code: the only place in the app where torch runs."""
