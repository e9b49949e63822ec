"""The history policy: what an Undo or Redo that puts back fitted shapes changes in the window.

The document's history holds the shapes of every fit, patch network fit and Reset (and those a
point edit left; :class:`app.state.ShapeState`); an undo or redo of one puts them back in the
document and this policy makes the window follow. It decides: a fit under way stops when the
shape it is fitting is replaced (its result is dropped, as Reset drops it), and says so; the
restored patch network is shown as a finished fit, with its stored report (or the network's
drawing cleared when there was none), with the RMS and seam numbers of its fit in the status
bar and without a new "fitted" line in the log (nothing was fitted); the fitted patch is measured
and drawn again by the fit display (``Document.fitted_changed``), the status bar's run labels
show what the fit of the shape now shown ended with (:mod:`app.window.run_labels`: its last
iteration and loss, "No fit" when none is back) and its message says what was undone or redone
and what shows now ("Undo Fit: no fitted shape (Start fits afresh)"); the loss plot shows the
curves kept with the shapes put back (those of the fits that made them; an empty plot when none
did). What a point edit changes
besides (the cloud) is the selection policy's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Slot

if TYPE_CHECKING:
    from app.window.hosts import HistoryHost


class HistoryPolicy(QObject):
    """Follows ``Document.shapes_restored`` for the window (see the module docstring)."""

    def __init__(self, window: HistoryHost):
        super().__init__(window)
        self._window = window

    @Slot(bool, bool)
    def on_shapes_restored(self, fitted_changed: bool, network_changed: bool) -> None:
        window = self._window
        document = window.document
        network, report = document.network, document.restored_network_report
        stopped = window.selection_policy.take_stopped()  # by a point edit's undo / redo
        if fitted_changed and window.controller.is_busy():
            window.controller.abandon()
            stopped.append("the fit")
        if network_changed and window.patch_controller.is_busy():
            window.patch_controller.abandon()
            stopped.append("the patch fit")
        shown = window.patch_controller.latest_shown
        network_shown = False
        if network is None and shown is not None:
            window.reset_patch_network()
        elif network is not None and (shown is None or shown.network is not network):
            window.patch_controller.show_saved(network, report, restored=True)
            network_shown = True
        if (fitted_changed or network_changed) and not network_shown:
            # the numbers of the fit that made the shape now shown, not those of the one gone
            patches = document.settings.fit_mode == "patches"
            window.run_labels.show_restored(
                document.restored_run_texts, document.restored_loss_history,
                document.network is not None if patches else document.fitted is not None)
        window.loss_plot.show_history(document.restored_loss_history)
        window.rebuild_tree()
        if not document.restored_by:  # the first "redo" of a point edit, when it is made
            return
        message = f"{document.restored_by}: {shown_text(document)}"
        if stopped:
            message += f"; {' and '.join(stopped)} under way stopped (its result is dropped)"
        window.report(message)


def shown_text(document) -> str:
    """What the mode on show now shows, after an undo or redo put shapes back:
    "back to one patch, 17 x 17 control points (degree 3 x 3), least-squares core; tolerance
    0.0265 (auto): met", "no fitted shape (Start fits afresh)", "back to a patch network of 22
    patches"."""
    from app.panels.result_text import result_text

    if document.settings.fit_mode == "patches":
        network = document.network
        if network is None:
            return "no patch network (Start fits one)"
        return f"back to a patch network of {network.patch_count} patches"
    if document.fitted is None:
        return "no fitted shape (Start fits afresh)"
    account = document.fitted_account
    if account is None:
        return "back to the fitted shape"
    return f"back to {result_text(account, document.units)}"
