"""Prompt templates and the LLM service config: rendering rules and start-up validation."""

from pathlib import Path

import pytest

from oricf.config import config_dir, load_config
from oricf.errors import ConfigError, InvalidInput
from oricf.services.llm.config import LlmConfig, load_prompt
from oricf.services.llm.prompt import PromptRenderer, PromptTemplate

TEMPLATE = PromptTemplate.model_validate({
    "format": {"header": "{system}\n\n", "turn": "Q: {question}\n{facts}\nA:",
               "answer": " {answer}\n\n", "stop": ["\n"]},
    "system": "Count people.",
    "facts": [{"key": "people_count", "known": "people: {value}", "unknown": "people: unknown",
               "stale": "people: unknown (was {value}, {age_s} s ago)", "max_age_s": 10}],
    "examples": [{"context": {"people_count": "2"}, "question": "How many?",
                  "answer": "I see 2 people."}],
})


def render(context: dict[str, str], question: str = "How many?",
           template: PromptTemplate = TEMPLATE) -> str:
    return PromptRenderer(template).render(question, context).text


def test_fixed_part_first_request_last() -> None:
    text = render({"people_count": "3"})
    assert text == ("Count people.\n\nQ: How many?\npeople: 2\nA: I see 2 people.\n\n"
                    "Q: How many?\npeople: 3\nA:")
    assert text.startswith(PromptRenderer(TEMPLATE).prefix)


@pytest.mark.parametrize(("context", "line"), [
    ({}, "people: unknown"),
    ({"people_count": ""}, "people: unknown"),
    ({"people_count": " Unknown "}, "people: unknown"),
    ({"people_count": "3", "people_count_age_s": "4"}, "people: 3"),
    ({"people_count": "3", "people_count_age_s": "12"}, "people: unknown (was 3, 12 s ago)"),
    ({"people_count": "3", "people_count_stale": "true"}, "people: unknown (was 3, ? s ago)"),
    ({"people_count": "3", "people_count_stale": "false"}, "people: 3"),
])
def test_fact_rendering(context: dict[str, str], line: str) -> None:
    assert render(context).endswith(f"\n{line}\nA:")


def test_stale_without_its_own_text_reads_as_unknown() -> None:
    fact = TEMPLATE.facts[0].model_copy(update={"stale": None})
    template = TEMPLATE.model_copy(update={"facts": [fact]})
    assert render({"people_count": "3", "people_count_age_s": "99"}, template=template
                  ).endswith("\npeople: unknown\nA:")


def test_other_context_keys_are_ignored_unless_the_template_renders_them() -> None:
    context = {"people_count": "3", "dogs": "2", "people_count_age_s": "1"}
    assert "dogs" not in render(context)
    template = TEMPLATE.model_copy(update={"other_facts": "{key}={value}"})
    assert render(context, template=template).endswith("\npeople: 3; dogs=2\nA:")


def test_questions_become_one_line() -> None:
    assert "Q: How many people\nare there?" not in render({}, "How many people\nare there?")
    assert "Q: How many people are there?\n" in render({}, "How many people\nare there?")


def test_bad_age_is_invalid_input() -> None:
    with pytest.raises(InvalidInput, match="must be a number of seconds"):
        render({"people_count": "3", "people_count_age_s": "soon"})
    with pytest.raises(InvalidInput, match=">= 0 seconds"):
        render({"people_count": "3", "people_count_age_s": "nan"})


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_unknown_placeholder_is_a_config_error_naming_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "p.yaml", 'format: {turn: "{question} {people}", answer: "{answer}"}\n')
    with pytest.raises(ConfigError, match=r"p\.yaml: format: .*unknown placeholder.*\{people\}"):
        load_prompt(path)


def test_unknown_key_in_a_prompt_file_is_refused(tmp_path: Path) -> None:
    path = write(tmp_path, "p.yaml", 'format: {turn: "{question}", answer: "{answer}"}\n'
                                     'sytem: typo\n')
    with pytest.raises(ConfigError, match=r"p\.yaml: sytem: unknown key"):
        load_prompt(path)


def test_a_model_without_a_prompt_is_a_config_error(tmp_path: Path) -> None:
    path = write(tmp_path, "llm.yaml", "model: {name: smollm2-135m-instruct}\n"
                                       "prompts: {gemma3-270m: p.yaml}\n")
    with pytest.raises(ConfigError, match="no prompt template for model 'smollm2-135m-instruct'"):
        load_config(path, LlmConfig)


def test_default_max_tokens_over_the_limit_is_a_config_error(tmp_path: Path) -> None:
    path = write(tmp_path, "llm.yaml", "prompts: {gemma3-270m: p.yaml}\n"
                                       "generation: {max_tokens: 300, max_tokens_limit: 200}\n")
    with pytest.raises(ConfigError, match="must not exceed max_tokens_limit"):
        load_config(path, LlmConfig)


def test_shipped_config_and_prompts_are_valid() -> None:
    config = load_config(config_dir() / "services" / "llm.yaml", LlmConfig)
    assert config.server.listen == "127.0.0.1:50053"  # this machine only by default
    for model, path in config.prompts.items():
        template = load_prompt(path)
        assert template.examples, model
        assert template.format.stop, model
    for path in (config_dir() / "prompts").glob("*.yaml"):
        load_prompt(path)
