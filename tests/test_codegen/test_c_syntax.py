"""C syntax of the generated code (codegen.c_syntax): safe names, comment text, exact literals."""

import numpy as np
import pytest
from test_render import HOSTILE

from codegen.c_syntax import C_KEYWORDS, C_LIBRARY_NAMES, comment_text, float_literal, int_literal, validate_name
from codegen.errors import InvalidNameError


class TestCommentText:
    def test_comment_text_keeps_only_whitelisted_characters(self):
        text = comment_text(HOSTILE)
        assert not set(text) & set("\\\n?*/#{};")
        assert text.startswith("m.json")

    def test_long_text_is_cut(self):
        assert len(comment_text("a" * 500)) == 200


class TestValidateName:
    @pytest.mark.parametrize("name", ["strtok", "memcpy", "int", "static", "int32_t", "isfoo", "FF", "Fb", "_fb",
                                      "1fb"])
    def test_reserved_library_and_upper_case_names_refused(self, name):
        with pytest.raises(InvalidNameError, match="--name"):
            validate_name(name)

    @pytest.mark.parametrize("name", ["ff", "fb", "ctl_q", "helmet_fb2", "a" + "b" * 31])
    def test_lower_case_identifiers_accepted(self, name):
        assert validate_name(name) == name

    def test_32_significant_characters_at_most(self):
        with pytest.raises(InvalidNameError, match="up to 31"):
            validate_name("a" * 33)

    @pytest.mark.parametrize("name", sorted(C_KEYWORDS | C_LIBRARY_NAMES))
    def test_every_keyword_and_library_name_refused(self, name):
        with pytest.raises(InvalidNameError):
            validate_name(name)

    def test_a_name_that_is_not_text_is_refused_without_echoing_it(self):
        with pytest.raises(InvalidNameError, match="found given name"):
            validate_name(42)


class TestLiterals:
    @pytest.mark.parametrize("value", [0.1, -2.5e-8, 1.0 / 3.0, 0.999999, 123456.789, -1e20, np.float32(0.7)])
    def test_float_literal_reads_back_to_the_same_float32(self, value):
        text = float_literal(value)
        assert text.endswith("f")
        assert np.float32(float(text[:-1])) == np.float32(value)

    @pytest.mark.parametrize("value, text", [(3.0, "3.0f"), (0.0, "0.0f"), (-2.0, "-2.0f"), (0.5, "0.5f"),
                                             (1e20, "1e+20f")])
    def test_float_literal_is_always_a_float_constant(self, value, text):
        assert float_literal(value) == text

    def test_int_literal_keeps_its_type_explicit(self):
        assert int_literal(-5) == "INT64_C(-5)"
        assert int_literal(np.int64(2**31 - 1), "INT32_C") == "INT32_C(2147483647)"
