"""configs/services/llm.yaml and the prompt files it names."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, model_validator

from oricf.config import FilePath, Schema, load_config
from oricf.services.llm.prompt import PromptTemplate
from oricf.services.runtime import ServiceConfig


class LlmModelSettings(Schema):
    name: str = Field("gemma3-270m", description="catalog name in configs/models.yaml")
    n_ctx: int = Field(1024, ge=128, le=32768, description="context window, tokens")
    n_batch: int = Field(256, ge=8, le=4096, description="prompt tokens evaluated per batch")
    threads: int = Field(1, ge=1, le=64, description="llama.cpp threads (generation and prompt)")
    omp_wait_policy: str = Field(
        "PASSIVE", pattern="^(PASSIVE|ACTIVE)$",
        description="OpenMP threads sleep (PASSIVE) or spin (ACTIVE) between parallel regions")
    reuse_prefix: bool = Field(
        True, description="keep the KV cache of the common prompt prefix between calls")
    gpu_layers: int = Field(
        0, ge=-1, description="layers offloaded to the GPU (-1: all); where llama.cpp was "
                              "built without a GPU back end, the model runs on the CPU and "
                              "one log line says so")


class GenerationSettings(Schema):
    max_tokens: int = Field(48, ge=1, description="when a request says 0")
    max_tokens_limit: int = Field(256, ge=1, description="larger requests are refused")
    temperature: float = Field(0.0, ge=0, le=2, description="when a request leaves it unset")
    top_k: int = Field(40, ge=0)
    top_p: float = Field(0.95, gt=0, le=1)
    min_p: float = Field(0.05, ge=0, le=1)
    repeat_penalty: float = Field(1.0, gt=0)

    @model_validator(mode="after")
    def _default_within_limit(self) -> GenerationSettings:
        if self.max_tokens > self.max_tokens_limit:
            raise ValueError("max_tokens must not exceed max_tokens_limit")
        return self


class JsonSchemaLimits(Schema):
    """What a response_format JSON Schema, and the llama.cpp grammar made from it, may cost.

    The ceilings are what was measured safe (docs/openai.md): llama.cpp's own parser gives
    up on deeper repetitions, and more alternatives make every token slower."""

    max_schema_chars: int = Field(16_384, ge=2, le=262_144, description="the schema's JSON text")
    max_depth: int = Field(32, ge=1, le=64, description="nested objects and lists in the schema")
    max_repeat: int = Field(
        256, ge=1, le=1000, description="minLength, maxLength, minItems, maxItems, "
        "minProperties, maxProperties, and each {m,n} of a pattern")
    max_pattern_expansion: int = Field(
        256, ge=1, le=4096, description="places in a pattern with its {m,n} written out")
    max_grammar_bytes: int = Field(
        65_536, ge=1024, le=1_048_576, description="the GBNF grammar made from the schema")
    max_grammar_rules: int = Field(
        32_768, ge=16, le=262_144, description="rules llama.cpp makes from that grammar")
    max_alternatives: int = Field(
        32, ge=1, le=256, description="parse stacks one position of the answer may need")


class InputLimits(Schema):
    max_prompt_chars: int = Field(2000, ge=1)
    max_facts: int = Field(32, ge=0, description="facts in one request")
    max_name_chars: int = Field(64, ge=1, description="characters in a fact's name")
    max_text_chars: int = Field(256, ge=1, description="characters in a fact's text value")
    max_stop_sequences: int = Field(4, ge=0)
    max_stop_chars: int = Field(32, ge=1)
    json_schema: JsonSchemaLimits = JsonSchemaLimits()


class QueueSettings(Schema):
    max_waiting: int = Field(
        4, ge=0, le=1024, description="callers waiting for the model; more: RESOURCE_EXHAUSTED")
    wait_timeout_s: float = Field(
        10.0, gt=0, le=3600, description="longest wait for the model; then RESOURCE_EXHAUSTED")


class LlmConfig(ServiceConfig):
    model: LlmModelSettings = LlmModelSettings()
    prompts: dict[str, FilePath] = Field(
        default_factory=dict, description="catalog name -> prompt template file for that model")
    generation: GenerationSettings = GenerationSettings()
    limits: InputLimits = InputLimits()
    queue: QueueSettings = QueueSettings()

    @model_validator(mode="after")
    def _prompt_for_model(self) -> LlmConfig:
        if self.model.name not in self.prompts:
            raise ValueError(f"prompts: no prompt template for model '{self.model.name}' "
                             f"(have: {', '.join(sorted(self.prompts)) or 'none'})")
        return self

    @property
    def prompt_path(self) -> Path:
        return self.prompts[self.model.name]


def load_prompt(path: Path) -> PromptTemplate:
    """Reads and validates a prompt file (ConfigError naming the file and key)."""
    return load_config(path, PromptTemplate)
