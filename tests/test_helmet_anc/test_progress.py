"""helmet_anc.progress: an elapsed-time line on a terminal only, never with --quiet or into a pipe."""

import io
import time

from helmet_anc.progress import busy


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_busy_draws_on_a_terminal_and_erases_its_line():
    stream = _Terminal()
    with busy("report", stream=stream, after_s=0.05, every_s=0.02):
        time.sleep(0.3)
    text = stream.getvalue()
    assert "\rreport ... 0 s" in text
    assert text.endswith("\r")  # the line is cleared before the command's own output


def test_busy_is_silent_when_quiet_short_or_not_a_terminal():
    for stream, quiet, seconds in ((_Terminal(), True, 0.2), (io.StringIO(), False, 0.2), (_Terminal(), False, 0.0)):
        with busy("report", quiet=quiet, stream=stream, after_s=0.05, every_s=0.02):
            time.sleep(seconds)
        assert stream.getvalue() == ""
