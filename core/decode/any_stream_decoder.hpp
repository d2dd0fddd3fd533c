// The stream decoder of a model known only at run time: one BasicStreamDecoder<Model> held in
// place, chosen when the model is (at start for a fixed model or a replay, at the first valid
// packet for a live "auto"). A loop that decodes many packets calls visit() once and runs on the
// model's type inside it (the daemon's decode worker does, a batch at a time), so no packet pays
// a branch on the model; process() visits per packet, for tools and tests.
// No allocation after construction (choose() constructs the new model's decoder in place).
#pragma once

#include <span>
#include <stdexcept>
#include <type_traits>
#include <variant>

#include "core/decode/stream_decoder.hpp"
#include "core/sensors/sensor_models.hpp"

namespace pandarcap {

class AnyStreamDecoder {
 public:
  AnyStreamDecoder(SensorModelId model, const Calibration& calibration,
                   const StreamDecoderConfig& config, FrameSink& sink) {
    choose(model, calibration, config, sink);
  }

  // Replaces the decoder with `model`'s (its counts start again).
  void choose(SensorModelId model, const Calibration& calibration,
              const StreamDecoderConfig& config, FrameSink& sink) {
    with_model(model, [&]<class M>(std::type_identity<M>) {
      decoder_.template emplace<BasicStreamDecoder<M>>(calibration, config, sink);
    });
    model_ = model;
  }

  SensorModelId model() const noexcept { return model_; }

  // f(BasicStreamDecoder<Model>&): one switch on the model.
  template <class F>
  decltype(auto) visit(F&& f) {
    return with_model(model_, [&]<class M>(std::type_identity<M>) -> decltype(auto) {
      return f(*std::get_if<BasicStreamDecoder<M>>(&decoder_));
    });
  }
  template <class F>
  decltype(auto) visit(F&& f) const {
    return with_model(model_, [&]<class M>(std::type_identity<M>) -> decltype(auto) {
      return f(*std::get_if<BasicStreamDecoder<M>>(&decoder_));
    });
  }

  RejectReason process(std::span<const std::uint8_t> payload) {
    return visit([&](auto& d) { return d.process(payload); });
  }
  void flush() {
    visit([](auto& d) { d.flush(); });
  }
  const StreamStats& stats() const {
    return visit([](const auto& d) -> const StreamStats& { return d.stats(); });
  }
  const SequenceStats& sequence() const {
    return visit([](const auto& d) -> const SequenceStats& { return d.sequence(); });
  }
  const AssemblerStats& frames() const {
    return visit([](const auto& d) -> const AssemblerStats& { return d.frames(); });
  }
  std::uint64_t packets_missing() const {
    return visit([](const auto& d) { return d.packets_missing(); });
  }
  DecoderTarget decoder_target() const {
    return visit([](const auto& d) { return d.decoder_target(); });
  }

 private:
  std::variant<std::monostate, BasicStreamDecoder<Pandar40P>, BasicStreamDecoder<Pandar64>,
               BasicStreamDecoder<PandarXT32>, BasicStreamDecoder<PandarXT16>,
               BasicStreamDecoder<PandarQT128>>
      decoder_;
  SensorModelId model_ = SensorModelId::kPandar40P;
};

}  // namespace pandarcap
