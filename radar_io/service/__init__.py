"""The live service: acquisition pipeline, websocket hub, REST API and the operator dashboard."""
