"""The main window's policies: small classes :class:`app.main_window.MainWindow` owns and delegates to.

The window builds the widgets and wires the signals; each module here decides one thing:

- :mod:`app.window.load_policy`: opening files (progress, cancel, what a loaded cloud changes in
  the settings, recent files);
- :mod:`app.window.settings_policy`: what a settings edit restarts, defers or switches;
- :mod:`app.window.export_policy`: what Export writes (and the window's screenshot);
- :mod:`app.window.session_policy`: saving and opening sessions;
- :mod:`app.window.selection_policy`: box and lasso selection, crop and delete (undoable);
- :mod:`app.window.history_policy`: what an Undo or Redo that puts back fitted shapes (a fit,
  Reset, a point edit) stops and shows;
- :mod:`app.window.fit_display`: what the viewport, readouts and status bar show of a fit;
- :mod:`app.window.text`: the short texts (file lists, durations) those messages share.

They only touch widgets, on the GUI thread; the engine's decisions stay in ``nurbs_core`` and
:mod:`app.state`.
"""
