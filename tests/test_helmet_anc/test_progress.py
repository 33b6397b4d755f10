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


def test_in_a_pipe_each_named_step_is_one_line():
    stream = io.StringIO()
    with busy("refine --auto", stream=stream) as step:
        step("step 1: diagnose (880.00x the noise floor)")
        step("step 1: adding delay and refitting")
    assert stream.getvalue() == ("refine --auto: step 1: diagnose (880.00x the noise floor)\n"
                                 "refine --auto: step 1: adding delay and refitting\n")


def test_on_a_terminal_the_spinner_names_the_step():
    stream = _Terminal()
    with busy("refine --auto", stream=stream, after_s=0.05, every_s=0.02) as step:
        step("step 2: adding delay and refitting")
        time.sleep(0.2)
    assert "\rrefine --auto: step 2: adding delay and refitting ... 0 s" in stream.getvalue()
    assert "\n" not in stream.getvalue()
